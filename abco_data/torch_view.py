"""A ``torch.utils.data.Dataset`` of transitions; the only module of abco_data importing torch.

Items are ``(s, s')`` for expert data and ``(s, a, s')`` for pre-demonstrations, as tensors:
observations keep their stored dtype (``uint8`` images stay ``uint8``, HWC), actions are int64.

Two modes:

- file-backed (default): each process opens its own h5py handle lazily, on its first read, so a
  ``DataLoader`` with workers gets one handle per worker (h5py handles must not cross a fork).
  Each handle is pinned to the file the dataset was opened on: a worker that finds another
  file under the path (the dataset was replaced on disk since) raises
  :class:`~abco_data.errors.DatasetChangedError` naming it, instead of pairing the new file's
  frames with the old file's actions;
- in memory (``in_memory=True``): the columns are read once, up front; for small datasets.

:func:`frames_tensor` gives a trainer's observation column as something it indexes with
tensors of rows: a tensor sharing an array's memory, or a :class:`FrameTensor` that draws
:class:`~abco_data.format.arrays.MazeFrames` a batch at a time.

Example:
    >>> import tempfile, os, torch, abco_data
    >>> path = abco_data.generate("abco/maze3x3-pre-v0", os.path.join(tempfile.mkdtemp(),
    ...     "p.hdf5"), progress=False, layouts=1, episodes_per_layout=2, reference_episodes=2)
    >>> view = abco_data.open_dataset(path).torch_dataset()
    >>> s, a, s1 = view[0]
    >>> s.shape, s.dtype, a.dtype
    (torch.Size([64, 64, 3]), torch.uint8, torch.int64)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from gymnasium import spaces
from torch.utils.data import Dataset as TorchDataset

from abco_data.format import ACTIONS, FileIdentity, LazyH5File, ObservationReader
from abco_data.format.arrays import DatasetArrays, MazeFrames
from abco_data.format.validation import check_observations

__all__ = ["TransitionDataset", "TransitionSource", "FrameTensor", "DeviceFrameTensor",
           "frames_tensor"]


class TransitionSource(Protocol):
    """What :class:`TransitionDataset` reads of an opened dataset (an :class:`abco_data.Dataset`
    is one; this module does not import :mod:`abco_data.dataset`, which imports it)."""

    @property
    def path(self) -> Path: ...
    @property
    def kind(self) -> str: ...
    @property
    def action_column(self) -> str: ...
    @property
    def observation_space(self) -> spaces.Space[Any]: ...
    @property
    def file_identity(self) -> FileIdentity | None: ...
    def transition_index(self) -> tuple[np.ndarray, np.ndarray]: ...
    def actions_of_transitions(self, *, idm_eval: bool = False) -> np.ndarray: ...
    def load_arrays(self) -> DatasetArrays: ...


class TransitionDataset(TorchDataset):
    """Transitions of one abco dataset file (made by ``Dataset.torch_dataset``).

    Args:
        dataset: The opened dataset (:func:`abco_data.open_dataset`).
        in_memory: Read every column into memory now instead of reading rows on demand.
        indices: Optional transition indices (e.g. from ``Dataset.sample_by_action``); item
            ``i`` is then transition ``indices[i]``.
        idm_eval_actions: For expert data, yield ``(s, a, s')`` with the expert's actions
            (for measuring IDM accuracy only, never for training).

    Raises:
        TypeError: ``dataset`` is not an opened dataset (a path, say).
    """

    def __init__(self, dataset: TransitionSource, in_memory: bool = False,
                 indices: np.ndarray | None = None, idm_eval_actions: bool = False) -> None:
        if not hasattr(dataset, "transition_index"):
            raise TypeError(f"TransitionDataset takes an opened dataset, not {dataset!r}: use"
                            " abco_data.open_dataset(path).torch_dataset()")
        self.path = dataset.path
        self.kind = dataset.kind
        self.with_actions = dataset.action_column == ACTIONS or idm_eval_actions
        self.obs_t, _ = dataset.transition_index()
        self.actions = (dataset.actions_of_transitions(idm_eval=True) if self.with_actions
                        else None)
        self.indices = None if indices is None else np.asarray(indices, dtype=np.int64)
        self.observations = dataset.load_arrays().observations if in_memory else None
        self.observation_space = dataset.observation_space
        # Opened by the process that reads (one per worker), pinned to the file the index above
        # came from.
        self._h5 = LazyH5File(self.path, dataset.file_identity)

    def __len__(self) -> int:
        return len(self.obs_t) if self.indices is None else len(self.indices)

    def _obs(self) -> np.ndarray | ObservationReader:
        return self.observations if self.observations is not None else self._h5.observations()

    def _rows(self, items: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``s`` and ``s'`` arrays for transition numbers ``items``, one sorted read each."""
        rows = self.obs_t[items]
        wanted = np.concatenate([rows, rows + 1])
        obs = self._obs()
        if isinstance(obs, np.ndarray):
            block = obs[wanted]
        else:  # read now: checked as load_arrays checks the whole column
            block = obs.rows(wanted)
            check_observations(block, self.observation_space, self.path)
        return block[: len(rows)], block[len(rows) :]

    def _items(self, idx: list[int]) -> list[tuple[torch.Tensor, ...]]:
        items = np.asarray(idx, dtype=np.int64)
        if np.any(items < -len(self)) or np.any(items >= len(self)):
            raise IndexError(f"transition index out of range for {len(self)} items")
        items %= len(self)
        if self.indices is not None:
            items = self.indices[items]
        s, s1 = self._rows(items)
        out: list[tuple[torch.Tensor, ...]] = []
        for j, k in enumerate(items):
            first, last = torch.from_numpy(s[j]), torch.from_numpy(s1[j])
            if self.actions is not None:
                out.append((first, torch.tensor(int(self.actions[k])), last))
            else:
                out.append((first, last))
        return out

    def __getitem__(self, i: int) -> tuple[torch.Tensor, ...]:
        return self._items([i])[0]

    def __getitems__(self, idx: list[int]) -> list[tuple[torch.Tensor, ...]]:
        """Batched fetch (used by ``DataLoader``): one sorted read per batch."""
        return self._items(idx)

    def close(self) -> None:
        """Close this process's handle, if open."""
        self._h5.close()


class FrameTensor:
    """:class:`~abco_data.format.arrays.MazeFrames` indexed like a ``uint8`` tensor of its frames.

    ``view[rows]`` (rows: a CPU integer tensor, an array or an int) is the tensor that
    ``torch.from_numpy(np.asarray(frames))[rows]`` would give, drawn for those rows only.

    Example:
        >>> import numpy as np
        >>> cells = np.full((1, 3, 3), 15, np.uint8)
        >>> frames, = MazeFrames.draw_columns([(cells, np.array([1]), np.array([[0, 0],
        ...     [0, 1]]))], height=6, width=6)
        >>> view = frames_tensor(frames)
        >>> view.shape, view.dtype, view[torch.tensor([1, 0])].shape
        (torch.Size([2, 6, 6, 3]), torch.uint8, torch.Size([2, 6, 6, 3]))
        >>> bool(torch.equal(view[torch.tensor([1])], torch.from_numpy(np.asarray(frames))[[1]]))
        True
    """

    def __init__(self, frames: MazeFrames) -> None:
        self.frames = frames

    @property
    def shape(self) -> torch.Size:
        """``(N, H, W, 3)``."""
        return torch.Size(self.frames.shape)

    @property
    def dtype(self) -> torch.dtype:
        """``torch.uint8``."""
        return torch.uint8

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, rows: torch.Tensor | np.ndarray | int) -> torch.Tensor:
        if isinstance(rows, torch.Tensor):
            rows = rows.cpu().numpy()
        return torch.from_numpy(self.frames[rows])


class DeviceFrameTensor:
    """:class:`~abco_data.format.arrays.MazeFrames` resident on a torch device, drawn there.

    What draws the frames (one background per layout, each row's background and agent cell,
    the dot's bytes) is moved to ``device`` once; ``view[rows]`` gathers the backgrounds and
    writes the dots on that device, so a GPU's minibatches never cross the bus as frames.
    Byte for byte the frames :class:`FrameTensor` draws.

    Example:
        >>> cells = np.full((1, 3, 3), 15, np.uint8)
        >>> frames, = MazeFrames.draw_columns([(cells, np.array([1]), np.array([[0, 0],
        ...     [0, 1]]))], height=6, width=6)
        >>> view = DeviceFrameTensor(frames, torch.device("cpu"))
        >>> rows = torch.tensor([1, 0, 1])
        >>> bool(torch.equal(view[rows], FrameTensor(frames)[rows]))
        True
    """

    def __init__(self, frames: MazeFrames, device: torch.device) -> None:
        self.device = device
        self._shape = torch.Size(frames.shape)
        self.backgrounds = torch.from_numpy(frames.backgrounds).to(device)
        self.background_of_row = torch.from_numpy(frames.background_of_row).long().to(device)
        self.cell_of_row = torch.from_numpy(frames.cell_of_row).long().to(device)
        self.dot_bytes = torch.from_numpy(frames.dot_bytes).long().to(device)
        self.dot_colour = torch.from_numpy(frames.dot_colour).to(device)

    @property
    def shape(self) -> torch.Size:
        """``(N, H, W, 3)``."""
        return self._shape

    @property
    def dtype(self) -> torch.dtype:
        """``torch.uint8``."""
        return torch.uint8

    def __len__(self) -> int:
        return self._shape[0]

    def __getitem__(self, rows: torch.Tensor | np.ndarray | int) -> torch.Tensor:
        index = torch.as_tensor(rows).to(self.device, torch.long)
        flat_rows = index.reshape(-1)
        out = self.backgrounds[self.background_of_row[flat_rows]]  # a gather: a new tensor
        if out.numel():
            dots = self.dot_bytes[self.cell_of_row[flat_rows]]
            out.view(len(flat_rows), -1).scatter_(
                1, dots, self.dot_colour.expand(len(flat_rows), -1))
        return out.reshape(*index.shape, *self._shape[1:])


def frames_tensor(observations: np.ndarray | MazeFrames, device: torch.device | str | None = None
                  ) -> torch.Tensor | FrameTensor | DeviceFrameTensor:  # fmt: skip
    """An observation column for indexing with tensors of rows: an array's tensor (sharing
    its memory) or, for :class:`~abco_data.format.arrays.MazeFrames`, a :class:`FrameTensor`.

    With an accelerator ``device`` (not the CPU) the column is moved there once, whole: a
    tensor on it, or a :class:`DeviceFrameTensor` that draws maze frames on it.
    """
    device = torch.device(device) if device is not None else None
    if device is not None and device.type != "cpu":
        if isinstance(observations, MazeFrames):
            return DeviceFrameTensor(observations, device)
        return torch.from_numpy(observations).to(device)
    if isinstance(observations, MazeFrames):
        return FrameTensor(observations)
    return torch.from_numpy(observations)
