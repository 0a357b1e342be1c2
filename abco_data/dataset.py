"""Reading abco datasets: :func:`open_dataset` and :class:`Dataset`, whose readers return the
in-memory records of :mod:`abco_data.format.arrays` (:class:`~abco_data.format.arrays.Episode`,
:class:`~abco_data.format.arrays.DatasetArrays`).

A transition ``k`` pairs observation rows ``obs_t[k]`` and ``obs_t[k] + 1`` of the flat
``observations`` column; both always lie in the same episode (each episode stores its ``T + 1``
observations, the final one included).

A maze dataset's episodes come grouped by layout, layouts in their split's order, so
:meth:`Dataset.first_layouts` can give a view of the first ``K`` layouts: a prefix of every
column, which its readers read and nothing beyond.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np
from gymnasium import spaces

from abco_data.checks.header import read_header, read_whole_column
from abco_data.errors import CorruptDatasetError, WrongKindError
from abco_data.format import (
    ACTIONS,
    EPISODE_COLUMNS,
    IDM_EVAL_ACTIONS,
    POSITIONS,
    REWARDS,
    TERMINATIONS,
    TRUNCATIONS,
    FileIdentity,
    LazyH5File,
    ObservationReader,
    action_column,
    episode_column,
    expected_rows,
    h5_column,
    hdf5_errors,
    open_h5,
)
from abco_data.format.arrays import DatasetArrays, Episode
from abco_data.format.validation import check_values
from abco_data.generation.reference import ReferenceReturns
from abco_data.registry import check_layout_count

if TYPE_CHECKING:  # imported when called: ``import abco_data`` does not import torch
    from abco_data.torch_view import TransitionDataset

__all__ = ["Dataset", "open_dataset"]


@dataclass(frozen=True, eq=False)
class Dataset:
    """An opened abco dataset file (see :func:`open_dataset`).

    Attributes:
        path: The file.
        id: Dataset id, e.g. ``"abco/maze5x5-expert-v0"``.
        kind: ``"expert"`` or ``"pre_demonstrations"``.
        env_id: Gymnasium id of the environment.
        num_episodes: Number of episodes.
        num_transitions: Number of transitions (``num_observations - num_episodes``).
        attrs: Every root attribute, JSON strings left as they are.
        observation_space: The env's observation space.
        action_space: The env's action space.
        reference: Reference returns for Performance ``P``.
        layouts_taken: ``K`` for a view of the first ``K`` layouts
            (:meth:`first_layouts`), whose counts and readers cover those layouts' episodes
            only; ``None`` for the whole file. ``attrs`` are the whole file's either way.
        file_identity: The file :func:`open_dataset` opened (device, inode, size,
            modification time); every later read, in any process, checks that ``path``
            still names it (:class:`~abco_data.errors.DatasetChangedError` if not).

    ``repr`` is one short line (id, path, kind, counts); ``attrs`` holds the rest.
    """

    path: Path
    id: str
    kind: str
    env_id: str
    num_episodes: int
    num_transitions: int
    attrs: Mapping[str, Any]
    observation_space: spaces.Space[Any]
    action_space: spaces.Discrete
    reference: ReferenceReturns
    layouts_taken: int | None = None
    file_identity: FileIdentity | None = field(default=None, repr=False)
    # Per instance, never copied (a view of ``dataclasses.replace`` gets its own).
    _index: dict[str, np.ndarray] = field(default_factory=dict, init=False, repr=False)
    _h5: LazyH5File = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_h5", LazyH5File(self.path, self.file_identity))

    def __repr__(self) -> str:
        taken = "" if self.layouts_taken is None else f", layouts_taken={self.layouts_taken}"
        return (f"Dataset(id={self.id!r}, path={str(self.path)!r}, kind={self.kind!r},"
                f" episodes={self.num_episodes}, transitions={self.num_transitions}{taken})")

    # -- file access -------------------------------------------------------------------------

    def _file(self) -> h5py.File:
        """An h5py handle owned by this process (reopened after a fork)."""
        return self._h5.file()

    def _observations(self) -> ObservationReader:
        """The observations column of this process's handle (palette decoded on read)."""
        return self._h5.observations()

    def close(self) -> None:
        """Close the file handle (it reopens on the next read)."""
        self._h5.close()

    @property
    def is_maze(self) -> bool:
        """Whether episodes carry maze layouts and positions."""
        return POSITIONS in self._file()

    @property
    def observation_palette(self) -> np.ndarray | None:
        """The ``(K, 3)`` palette of palette-encoded observations, else None."""
        return self._observations().palette

    @property
    def action_column(self) -> str:
        """``"actions"`` (pre-demonstrations) or ``"idm_eval_actions"`` (expert data)."""
        return action_column(self.kind)

    def _episode_index(self) -> dict[str, np.ndarray]:
        if not self._index:
            f = self._file()
            with hdf5_errors(self.path, "episode offsets"):
                index = {key: read_whole_column(h5_column(f, episode_column(key)), self.path,
                                                self.num_episodes)
                         for key in EPISODE_COLUMNS}
            self._index.update(index)
        return self._index

    # -- layouts ------------------------------------------------------------------------------

    def _layout_groups(self) -> np.ndarray:
        """First episode of each layout's run of episodes (mazes), checked to be grouped."""
        if not self.is_maze:
            raise WrongKindError(f"{self.path}: {self.id} holds {self.env_id} data, which has"
                                 " no maze layouts")
        if not self.num_episodes:
            return np.zeros(0, dtype=np.int64)
        with hdf5_errors(self.path, "column episodes/layout_index"):
            column = h5_column(self._file(), episode_column("layout_index"))
            order = read_whole_column(column, self.path, self.num_episodes)
        starts = np.flatnonzero(np.concatenate([[True], order[1:] != order[:-1]]))
        if len(np.unique(order[starts])) != len(starts):
            raise CorruptDatasetError(f"{self.path}: episodes are not grouped by layout (a"
                                      " layout index comes back after another one)")
        return starts

    @property
    def num_layouts(self) -> int:
        """Distinct layouts of a maze dataset (of this view).

        Raises:
            WrongKindError: Not a maze dataset.
        """
        return len(self._layout_groups())

    def first_layouts(self, k: int) -> Dataset:
        """A view of the episodes of the first ``k`` layouts of this maze dataset.

        Layouts count in file order (the split's order: layout ``j`` of the procedural
        datasets is ``procedural_layouts(n, K)[j]``). The view's episodes, transitions and
        observations are a prefix of the file's; ``load_arrays``, ``episodes``,
        ``read_transitions``, ``sample_by_action``, ``torch_dataset`` and
        :func:`~abco_data.check_dataset` see that prefix only, and read nothing beyond it.

        Args:
            k: How many layouts, from 1 to :attr:`num_layouts`.

        Returns:
            A new :class:`Dataset` of the same file (``layouts_taken == k``).

        Raises:
            ValueError: ``k`` is not an integer from 1 to :attr:`num_layouts`.
            WrongKindError: Not a maze dataset.
            CorruptDatasetError: Episodes not grouped by layout.

        Example:
            >>> import tempfile, os, abco_data
            >>> path = abco_data.generate("abco/maze5x5-procedural-expert-v0", os.path.join(
            ...     tempfile.mkdtemp(), "p.hdf5"), progress=False, layouts=4,
            ...     reference_episodes=1)
            >>> ds = abco_data.open_dataset(path)
            >>> ds.num_layouts, ds.first_layouts(2).num_episodes
            (4, 2)
            >>> ds.first_layouts(5)  # doctest: +ELLIPSIS
            Traceback (most recent call last):
            ValueError: ...: layouts=5 is out of range: abco/maze5x5-procedural-expert-v0 has 4 layouts; take from 1 to 4
        """  # noqa: E501
        starts = self._layout_groups()
        check_layout_count(k, len(starts), f"{self.path}: layouts={k!r}", self.id)
        n_ep = int(starts[k]) if k < len(starts) else self.num_episodes
        n_tr = int(self._episode_index()["length"][:n_ep].sum())
        return dataclasses.replace(self, num_episodes=n_ep, num_transitions=n_tr,
                                   layouts_taken=int(k))

    # -- episodes -----------------------------------------------------------------------------

    def episode(self, i: int) -> Episode:
        """Episode ``i`` (negative indices count from the end).

        Raises:
            IndexError: ``i`` out of range.
        """
        if not -self.num_episodes <= i < self.num_episodes:
            raise IndexError(f"episode {i} out of range: {self.path} has"
                             f" {self.num_episodes} episodes")
        i %= self.num_episodes
        idx, f = self._episode_index(), self._file()
        o, t, n = (int(idx[k][i]) for k in ("obs_offset", "transition_offset", "length"))
        maze = POSITIONS in f
        with hdf5_errors(self.path, f"episode {i}"):
            col = functools.partial(h5_column, f)
            episode = Episode(
                index=i, seed=int(idx["seed"][i]), observations=self._read_obs(o, o + n + 1),
                actions=col(ACTIONS)[t : t + n] if self.action_column == ACTIONS else None,
                rewards=col(REWARDS)[t : t + n], terminations=col(TERMINATIONS)[t : t + n],
                truncations=col(TRUNCATIONS)[t : t + n], episode_return=float(idx["return"][i]),
                layout=col(episode_column("layout"))[i] if maze else None,
                layout_index=int(col(episode_column("layout_index"))[i]) if maze else None,
                positions=col(POSITIONS)[o : o + n + 1] if maze else None,
            )
        check_values(DatasetArrays.of_episode(episode),
                     action_count=int(self.action_space.n), path=f"{self.path} (episode {i})",
                     observation_space=self.observation_space)
        return episode

    def _read_obs(self, start: int, stop: int, out: np.ndarray | None = None) -> np.ndarray:
        return self._observations().read(start, stop, out)

    def episodes(self) -> Iterator[Episode]:
        """Every episode, in order."""
        for i in range(self.num_episodes):
            yield self.episode(i)

    # -- flat views ---------------------------------------------------------------------------

    def load_arrays(self, *, observations: bool = True) -> DatasetArrays:
        """Every column in memory as numpy arrays (each read into one allocation).

        Palette-encoded observations are decoded chunk by chunk into the one output array;
        with ``observations=False`` none are read (the column comes back with zero rows).
        """
        f = self._file()
        reader = self._observations()
        rows = expected_rows(self.kind, self.num_episodes, self.num_transitions,
                             maze=POSITIONS in f)  # a view's prefix, or every row

        def column(name: str) -> np.ndarray:
            return read_whole_column(h5_column(f, name), self.path, rows.get(name))

        def optional(name: str) -> np.ndarray | None:
            return column(name) if name in f else None

        n_obs = self.num_transitions + self.num_episodes if observations else 0
        with hdf5_errors(self.path, "columns"):  # the observations last, as they are read
            arrays = DatasetArrays(
                actions=optional(ACTIONS), idm_eval_actions=optional(IDM_EVAL_ACTIONS),
                rewards=column(REWARDS), terminations=column(TERMINATIONS),
                truncations=column(TRUNCATIONS),
                episode_starts=column(episode_column("obs_offset")),
                episode_transition_starts=column(episode_column("transition_offset")),
                episode_lengths=column(episode_column("length")),
                episode_seeds=column(episode_column("seed")),
                episode_returns=column(episode_column("return")), positions=optional(POSITIONS),
                layouts=optional(episode_column("layout")),
                layout_indices=optional(episode_column("layout_index")),
                observations=self._read_obs(0, n_obs, np.empty((n_obs, *reader.shape[1:]),
                                                               dtype=reader.dtype)))
        check_values(arrays, action_count=int(self.action_space.n), path=self.path,
                     observation_space=self.observation_space)
        return arrays

    def transition_index(self) -> tuple[np.ndarray, np.ndarray]:
        """``(obs_t, obs_t1)``: rows of ``observations`` of each transition's ``s`` and ``s'``.

        Both are int64 arrays of length ``num_transitions``; ``obs_t1 = obs_t + 1`` and never
        crosses into the next episode.
        """
        idx = self._episode_index()
        shift = np.repeat(idx["obs_offset"] - idx["transition_offset"], idx["length"])
        obs_t = np.arange(self.num_transitions, dtype=np.int64) + shift
        return obs_t, obs_t + 1

    def read_transitions(self, indices: np.ndarray | Sequence[int]
                         ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """``(s, a, s')`` of the given transitions, read with one sorted HDF5 read.

        ``a`` is ``None`` for expert data. Rows come back in the order of ``indices``.
        """
        items = np.asarray(indices, dtype=np.int64)
        if items.size and (items.min() < 0 or items.max() >= self.num_transitions):
            raise IndexError(f"transition index out of range: {self.path} has"
                             f" {self.num_transitions} transitions")
        obs_t, _ = self.transition_index()
        rows = obs_t[items]
        block = self._observations().rows(np.concatenate([rows, rows + 1]))
        actions = None
        if self.action_column == ACTIONS:
            actions = self.actions_of_transitions()[items]
        return block[: len(rows)], actions, block[len(rows) :]

    def actions_of_transitions(self, *, idm_eval: bool = False) -> np.ndarray:
        """The action of every transition (int64).

        Args:
            idm_eval: Allow an expert dataset's ``idm_eval_actions`` (for measuring IDM
                accuracy only, never for training).

        Raises:
            WrongKindError: An expert dataset and ``idm_eval`` is False.
        """
        if self.kind == "expert" and not idm_eval:
            raise WrongKindError(
                f"{self.path}: expert data has no training actions; its idm_eval_actions are"
                " for measuring IDM accuracy only (pass idm_eval=True to read them)")
        with hdf5_errors(self.path, f"column {self.action_column}"):
            actions = read_whole_column(h5_column(self._file(), self.action_column), self.path,
                                        self.num_transitions)
        if len(actions) and (actions.min() < 0 or actions.max() >= self.action_space.n):
            raise CorruptDatasetError(f"{self.path}: {self.action_column} outside the action"
                                      f" space {self.action_space}")
        return actions

    def sample_by_action(self, counts: Sequence[int] | Mapping[int, int] | np.ndarray,
                         rng: np.random.Generator | int | None) -> np.ndarray:
        """Transition indices with ``counts[a]`` transitions of each action class ``a``.

        Uniform within a class, without replacement unless a class has fewer transitions than
        asked. The result is in random order.

        Args:
            counts: Per action: a sequence indexed by action, or a mapping action -> count.
            rng: A numpy Generator or a seed.

        Raises:
            ValueError: A positive count for an action that never occurs.
            WrongKindError: An expert dataset (it has no training actions).
        """
        rng = np.random.default_rng(rng)
        actions = self.actions_of_transitions()
        items = counts.items() if isinstance(counts, Mapping) else enumerate(counts)
        picked = []
        for a, c in items:
            c = int(c)
            if c <= 0:
                continue
            rows = np.flatnonzero(actions == int(a))
            if not len(rows):
                raise ValueError(f"{self.path}: no transition has action {a}, {c} asked")
            picked.append(rng.choice(rows, size=c, replace=c > len(rows)))
        out = np.concatenate(picked) if picked else np.empty(0, dtype=np.int64)
        return rng.permutation(out).astype(np.int64)

    def torch_dataset(self, in_memory: bool = False, **kwargs: Any) -> TransitionDataset:
        """A ``torch.utils.data.Dataset`` of transitions (see :mod:`abco_data.torch_view`)."""
        from abco_data.torch_view import TransitionDataset

        return TransitionDataset(self, in_memory=in_memory, **kwargs)


def open_dataset(path: str | os.PathLike[str], *, dataset_id: str | None = None,
                 kind: str | None = None) -> Dataset:
    """Open and validate an abco dataset file.

    Checks the format name and version, the required attributes and columns, that the id
    agrees with the env and kind, and that the episode offsets agree with the column lengths
    (reading every value, and the checksum, is left to :func:`abco_data.check_dataset` and
    :func:`abco_data.verify`).

    Args:
        path: The ``.hdf5`` file.
        dataset_id: If given, the id the file must hold.
        kind: If given, the kind the file must be (``expert`` | ``pre_demonstrations``).

    Raises:
        DatasetFileNotFoundError: No such file (also a ``FileNotFoundError``).
        DatasetReadError: Not a regular file, or not readable.
        CorruptDatasetError: Truncated, corrupt, not an abco dataset, or inconsistent.
        FormatVersionError: Another ``format_version``.
        WrongKindError: Another id or kind than asked for.
    """
    path = Path(path)
    with open_h5(path) as f, hdf5_errors(path, "dataset metadata"):
        header = read_header(f, path, dataset_id=dataset_id, kind=kind)
        identity = FileIdentity.of(f)
    attrs = header.attrs
    return Dataset(
        path=path, id=attrs["dataset_id"], kind=attrs["kind"], env_id=attrs["env_id"],
        num_episodes=attrs["num_episodes"], num_transitions=attrs["num_transitions"],
        attrs=attrs, observation_space=header.observation_space,
        action_space=header.action_space, reference=header.reference, file_identity=identity)
