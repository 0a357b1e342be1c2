"""A run's training data: its two datasets resolved, checked, loaded and subsampled.

:func:`resolve_dataset` is the one place that turns ``--expert-data`` / ``--pre-data`` (a
file, a dataset id, or nothing for the env's own dataset) into an open
:class:`abco_data.Dataset`; the trainer and ``abco bench`` both use it.
:class:`TrainingData` is what a :class:`~abco_train.methods.base.Method` receives: numpy arrays,
no torch. A maze's RGB frames stay what draws them (:class:`abco_data.format.arrays.MazeFrames`: one
background per layout, the agent's cell per frame), drawn a minibatch at a time, so memory
grows with the episodes and not with their frames (12 KiB each at 64x64, gigabytes for the
first 10,000 procedural layouts). Every frame drawn is checked once against the file's own,
as it loads: a file whose frames do not re-render is kept decoded instead, so training sees
the file's frames either way.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

import abco_data
import abco_envs
from abco_data.errors import DatasetFileNotFoundError
from abco_data.format import LazyH5File
from abco_data.format.arrays import MazeFrames
from abco_envs.maze.layout import layout_hash
from abco_train.config.run import ConfigError, RunConfig

__all__ = ["TrainingData", "resolve_dataset", "looks_like_path", "check_dataset_paths",
           "load_training_data", "distinct_layouts", "KINDS", "TRAIN_EVAL_LAYOUTS"]  # fmt: skip

#: Dataset kinds of a run, by the role they play.
KINDS = {"expert": "expert", "pre": "pre_demonstrations"}
#: A run on the first K layouts (``--layouts``) is evaluated on its training layouts (the
#: ``train`` evaluation, whose rollouts are also ABCO's post-demonstrations) on the first
#: ``min(K, TRAIN_EVAL_LAYOUTS)`` of them: as many as the pool's train split has.
TRAIN_EVAL_LAYOUTS = 100


#: File name endings of HDF5 datasets: a ``--expert-data``/``--pre-data`` value ending so is a
#: path, never a dataset id.
HDF5_SUFFIXES = (".hdf5", ".h5", ".hdf")


def looks_like_path(ref: str) -> bool:
    """Whether a dataset argument is a file path rather than a dataset id (``abco/NAME-v0``,
    ``local/NAME-v0``): an HDF5 file name, a path from the root, home or the current
    folder, or more than one folder deep.

    Example:
        >>> [looks_like_path(r) for r in ("data/nope.hdf5", "abco/maze5x5-expert-v0", "./x")]
        [True, False, True]
    """
    return (ref.lower().endswith(HDF5_SUFFIXES) or ref.startswith(("/", "./", "../", "~"))
            or ref.count("/") > 1 or os.sep in ref.replace("/", ""))


def _no_such_file(ref: str | None) -> bool:
    """Whether a dataset argument is a path (:func:`looks_like_path`) that names no file."""
    return ref is not None and looks_like_path(ref) and not Path(ref).is_file()


def check_dataset_paths(config: RunConfig) -> None:
    """Refuse a ``--expert-data``/``--pre-data`` path that names no file, before a run touches
    its folder.

    Raises:
        DatasetFileNotFoundError: ``no such file: PATH``, naming the option.
    """
    for flag, ref in (("--expert-data", config.expert_data), ("--pre-data", config.pre_data)):
        if _no_such_file(ref):
            raise DatasetFileNotFoundError(f"{flag}: no such file: {ref}")


def resolve_dataset(
    ref: str | None,
    env_id: str,
    kind: str,
    *,
    cache_dir: str | None = None,
    progress: bool = False,
    cached_only: bool = False,
) -> abco_data.Dataset:
    """A run's dataset: the file ``ref``, the dataset id ``ref`` (abco's, or a user dataset's:
    :func:`abco_data.record`), or the env's own dataset.

    Args:
        ref: A path to an HDF5 file, a dataset id (a user id, ``local/NAME-v0``, is found in
            the user manifest of ``cache_dir``), or ``None`` (the env's ``kind`` dataset).
        env_id: The run's environment.
        kind: ``"expert"`` or ``"pre_demonstrations"``.
        cache_dir: abco dataset cache (default ``$ABCO_DATA_HOME``).
        progress: Show download/generation progress.
        cached_only: Never fetch or generate: read the cache only (raises if missing).

    Raises:
        abco_data.DatasetError: The file or id is unusable (missing, damaged, another kind or
            environment, a checksum mismatch, non-finite values); the message names it.
    """
    if _no_such_file(ref):
        raise DatasetFileNotFoundError(f"no such file: {ref}")
    if ref is not None and (Path(ref).is_file() or abco_data.is_user_id(ref)):
        # A file given by hand, or a user dataset's (its bytes checked against the user
        # manifest first), is checked like one from the cache, before any training: its kind,
        # environment, format version, checksum (when its id is known) and values.
        if Path(ref).is_file():
            return abco_data.check_dataset(ref, kind=kind, env_id=env_id)
        from abco_data.user.datasets import user_dataset_file

        return abco_data.check_dataset(user_dataset_file(ref, cache_dir), kind=kind,
                                       env_id=env_id, dataset_id=ref)  # fmt: skip
    dataset_id = ref or abco_data.dataset_id(env_id, kind)
    if cached_only:
        home = Path(cache_dir) if cache_dir else abco_data.data_home()
        return abco_data.open_dataset(home / abco_data.spec(dataset_id).filename)
    wanted = abco_data.spec(dataset_id)  # an id names its kind and env: check before fetching
    if wanted.kind != kind or abco_envs.env_name(wanted.env_id) != abco_envs.env_name(env_id):
        raise abco_data.WrongKindError(
            f"{dataset_id} holds {wanted.kind} of {wanted.env_id}; this run needs {kind} of "
            f"{env_id}")  # fmt: skip
    # Loaded files are checked against the manifest's sha256 (or regenerated) by ``load``.
    return abco_data.load(dataset_id, cache_dir=cache_dir, progress=progress)


@dataclass(frozen=True)
class TrainingData:
    """The datasets of a run, in memory, as numpy arrays.

    Attributes:
        env_id: The environment.
        env_kwargs: Arguments the datasets were recorded with (mazes: ``obs_type``,
            ``image_size``); evaluation uses the same.
        observation_space: The datasets' observation space.
        n_actions: Size of the discrete action space.
        reference: Expert and random reference returns (per layout for mazes).
        pre_obs: Pre-demonstration observations, every episode's ``T + 1`` rows: an array, or
            for maze frames :class:`~abco_data.format.arrays.MazeFrames` (index it with rows:
            ``pre_obs[rows]`` is an array; methods index it with tensors through
            :func:`abco_data.torch_view.frames_tensor`).
        pre_t: Row of ``s_t`` of each pre-demonstration transition (``s_t+1`` is the next).
        pre_actions: The true action of each pre-demonstration transition.
        expert_obs: Expert observations, every episode's ``T + 1`` rows (as ``pre_obs``).
        expert_t: Row of ``s_t`` of each expert transition.
        expert_eval_actions: The expert's true actions: for measuring IDM accuracy (and for
            ``bc``, the supervised reference) only, never as labels of an IfO method.
        layouts: Mazes with ``--layouts``: K, the number of layouts trained on; else ``None``.
        train_layouts: Mazes with ``--layouts``: the ``(k, n, n)`` layouts of the ``train``
            evaluation (the first ``min(K, TRAIN_EVAL_LAYOUTS)`` training layouts, whose
            references ``reference`` then includes); ``None``: the pool's train split.
        expert_layout_ids: Mazes: the structural ids of the layouts the run's expert episodes
            play (a validation evaluation leaves them out).
    """

    env_id: str
    env_kwargs: dict[str, Any]
    observation_space: Any
    n_actions: int
    reference: abco_data.ReferenceReturns
    pre_obs: np.ndarray | MazeFrames
    pre_t: np.ndarray
    pre_actions: np.ndarray
    expert_obs: np.ndarray | MazeFrames
    expert_t: np.ndarray
    expert_eval_actions: np.ndarray
    layouts: int | None = None
    train_layouts: np.ndarray | None = None
    expert_layout_ids: frozenset[str] = frozenset()

    @property
    def is_maze(self) -> bool:
        """Whether the data comes from a maze (references per layout)."""
        return self.reference.layout_ids is not None


def _frame_size(dataset: abco_data.Dataset) -> tuple[int, int] | None:
    """``(H, W)`` of a maze dataset's RGB frames (:class:`MazeFrames` can draw them), else
    None."""
    space = dataset.observation_space
    if (isinstance(space, spaces.Box) and space.dtype == np.uint8 and len(space.shape) == 3
            and space.shape[-1] == 3 and dataset.is_maze):
        return space.shape[0], space.shape[1]
    return None


def _arrays(dataset: abco_data.Dataset) -> abco_data.DatasetArrays:
    """Every column of ``dataset``; maze frames left unread (:func:`_observations` draws
    them)."""
    return dataset.load_arrays(observations=_frame_size(dataset) is None)


def _columns(dataset: abco_data.Dataset, arrays: abco_data.DatasetArrays,
             episodes: int | None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``s_t`` rows and actions of the transitions of a dataset's first ``episodes``
    episodes."""
    obs_t, _ = dataset.transition_index()
    actions = dataset.actions_of_transitions(idm_eval=True)
    if episodes is not None:
        n = int(arrays.episode_lengths[:episodes].sum())
        obs_t, actions = obs_t[:n], actions[:n]
    return obs_t, actions


def _redraws_file(frames: MazeFrames, dataset: abco_data.Dataset) -> bool:
    """Whether every frame drawn is the file's (read and compared a block at a time)."""
    handle = LazyH5File(dataset.path, dataset.file_identity)
    try:
        reader = handle.observations()
        return frames.first_difference(reader.read) is None
    finally:
        handle.close()


def _maze_part(arrays: abco_data.DatasetArrays) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Layouts, episode lengths and agent positions: what draws a maze's frames."""
    assert arrays.layouts is not None and arrays.positions is not None, (
        "a maze's arrays carry layouts and positions (load_arrays checks them)")
    return arrays.layouts, arrays.episode_lengths, arrays.positions


def _observations(datasets: list[abco_data.Dataset], arrays: list[abco_data.DatasetArrays]
                  ) -> list[np.ndarray | MazeFrames]:  # fmt: skip
    """Each dataset's observation column: maze frames drawn (one background per layout,
    shared by datasets of one frame size) when they are the file's; else decoded."""
    columns: list[np.ndarray | MazeFrames] = [a.observations for a in arrays]
    groups: dict[tuple[int, int], list[int]] = {}
    for i, dataset in enumerate(datasets):
        size = _frame_size(dataset)
        if size is not None:
            groups.setdefault(size, []).append(i)
    for (height, width), members in groups.items():
        try:
            drawn: list[MazeFrames | None] = list(MazeFrames.draw_columns(
                [_maze_part(arrays[i]) for i in members], height=height, width=width))
        except ValueError:  # frames too small for the maze: not the renderer's
            drawn = [None] * len(members)
        for i, frames in zip(members, drawn):
            if frames is not None and _redraws_file(frames, datasets[i]):
                columns[i] = frames
            else:  # the file's own frames, decoded, as ever
                columns[i] = datasets[i].load_arrays().observations
    return columns


def _first_layouts(dataset: abco_data.Dataset, k: int, flag: str) -> abco_data.Dataset:
    """The view of ``dataset``'s first ``k`` layouts, or a ConfigError naming ``flag``."""
    try:
        return dataset.first_layouts(k)
    except (ValueError, abco_data.WrongKindError) as exc:
        raise ConfigError(f"--layouts {k} with {flag} {dataset.id or dataset.path}: {exc}"
                          ) from None  # fmt: skip


def distinct_layouts(arrays: abco_data.DatasetArrays, count: int) -> np.ndarray:
    """The first ``count`` distinct layouts of a maze dataset's episodes, in file order."""
    if arrays.layouts is None or arrays.layout_indices is None:
        raise ValueError("not a maze dataset: its episodes carry no layouts")
    starts = np.flatnonzero(np.r_[True, arrays.layout_indices[1:] != arrays.layout_indices[:-1]])
    return np.ascontiguousarray(arrays.layouts[starts[:count]])


def shown_layout_ids(arrays: abco_data.DatasetArrays, episodes: int | None) -> frozenset[str]:
    """The structural ids of the layouts of a maze dataset's first ``episodes`` episodes (all:
    ``None``); empty for other datasets."""
    if arrays.layouts is None or arrays.layout_indices is None:
        return frozenset()
    _, first = np.unique(arrays.layout_indices[:episodes], return_index=True)
    return frozenset(layout_hash(cells) for cells in arrays.layouts[first])


def load_training_data(config: RunConfig) -> TrainingData:
    """Load (download or generate if needed) and subsample the run's two datasets.

    With ``config.layouts`` (K), both datasets are cut to their first K layouts
    (:meth:`abco_data.Dataset.first_layouts`), and the ``train`` evaluation moves to the
    first ``min(K, TRAIN_EVAL_LAYOUTS)`` of them, their references computed by
    :func:`abco_data.layout_reference` and added to the dataset's.

    Raises:
        ConfigError: K is more than a dataset's layouts, or a dataset is not a maze's.
        abco_data.DatasetError: A dataset is unusable (see :func:`resolve_dataset`).
    """
    progress = not config.quiet
    expert = resolve_dataset(config.expert_data, config.env, KINDS["expert"],
                             cache_dir=config.cache_dir, progress=progress)  # fmt: skip
    pre = resolve_dataset(config.pre_data, config.env, KINDS["pre"],
                          cache_dir=config.cache_dir, progress=progress)  # fmt: skip
    reference, train_layouts = expert.reference, None
    if config.layouts is not None:
        expert = _first_layouts(expert, config.layouts, "--expert-data")
        pre = _first_layouts(pre, config.layouts, "--pre-data")
    pre_arrays, arrays = _arrays(pre), _arrays(expert)
    pre_obs, expert_obs = _observations([pre, expert], [pre_arrays, arrays])
    pre_t, pre_actions = _columns(pre, pre_arrays, None)
    if config.pre_transitions is not None:
        pre_t, pre_actions = pre_t[: config.pre_transitions], pre_actions[: config.pre_transitions]
    expert_t, expert_actions = _columns(expert, arrays, config.expert_episodes)
    if config.layouts is not None:
        train_layouts = distinct_layouts(arrays, min(config.layouts, TRAIN_EVAL_LAYOUTS))
        reference = reference.extended(abco_data.layout_reference(train_layouts, "training"))
    return TrainingData(
        env_id=config.env, env_kwargs=json.loads(expert.attrs.get("env_kwargs", "{}") or "{}"),
        observation_space=expert.observation_space, n_actions=int(expert.action_space.n),
        reference=reference, pre_obs=pre_obs, pre_t=pre_t, pre_actions=pre_actions,
        expert_obs=expert_obs, expert_t=expert_t, expert_eval_actions=expert_actions,
        layouts=config.layouts, train_layouts=train_layouts,
        expert_layout_ids=shown_layout_ids(arrays, config.expert_episodes),
    )  # fmt: skip
