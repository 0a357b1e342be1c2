"""The rules every value of a dataset obeys, checked by every reader of whole columns.

:func:`check_values` runs on the arrays of a whole file (``Dataset.load_arrays``) and on those
of one episode (``Dataset.episode``): finite rewards, returns and observations, actions in the
action space, episodes that end on their last transition and only there, returns that are the
sums of the rewards, observations inside the observation space, and for mazes agent positions
inside the grid, valid layouts and layout indices. :func:`check_observations` is the part the
torch view applies to each batch. :func:`abco_data.verify` adds what needs more than the
arrays (every maze move against the walls, every frame re-rendered).

Example:
    >>> import numpy as np
    >>> from abco_data.format.arrays import DatasetArrays
    >>> one = np.array([0]); a = DatasetArrays(
    ...     observations=np.zeros((2, 1), np.float32), actions=np.array([1]),
    ...     idm_eval_actions=None, rewards=np.array([np.nan]), terminations=np.array([True]),
    ...     truncations=np.array([False]), episode_starts=one, episode_transition_starts=one,
    ...     episode_lengths=np.array([1]), episode_seeds=one, episode_returns=np.array([0.0]))
    >>> check_values(a, action_count=2, path="x.hdf5")
    Traceback (most recent call last):
    abco_data.errors.CorruptDatasetError: x.hdf5: rewards hold NaN or infinite values
"""

from __future__ import annotations

import os
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from abco_data.errors import CorruptDatasetError
from abco_data.format.arrays import DatasetArrays

__all__ = ["check_values", "check_observations", "maze_columns", "MazeColumns",
           "MAZE_CELL_BITS"]

#: A maze cell is a bit set of its open sides (N=1, E=2, S=4, W=8).
MAZE_CELL_BITS = 15


def _finite(values: np.ndarray | None, name: str, path: object) -> None:
    if values is not None and values.dtype.kind == "f" and not np.isfinite(values).all():
        raise CorruptDatasetError(f"{path}: {name} hold NaN or infinite values")


def _check_episode_ends(a: DatasetArrays, path: object) -> None:
    if not len(a.episode_lengths):
        return
    ends = a.episode_transition_starts + a.episode_lengths - 1
    last = np.zeros(len(a.rewards), dtype=bool)
    last[ends] = True
    if np.any((a.terminations | a.truncations) & ~last):
        raise CorruptDatasetError(f"{path}: an episode ends before its last transition")
    if not np.all(a.terminations[ends] | a.truncations[ends]):
        raise CorruptDatasetError(f"{path}: an episode's last transition neither terminates"
                                  " nor truncates it")
    sums = np.add.reduceat(a.rewards, a.episode_transition_starts)
    if not np.allclose(sums, a.episode_returns, rtol=0, atol=1e-9):
        raise CorruptDatasetError(f"{path}: stored episode returns differ from reward sums")


class MazeColumns(NamedTuple):
    """The maze-only columns of :class:`~abco_data.format.arrays.DatasetArrays`, all present."""

    positions: np.ndarray
    layouts: np.ndarray
    layout_indices: np.ndarray


def maze_columns(a: DatasetArrays, path: object) -> MazeColumns | None:
    """The maze columns of ``a``, or None if it holds none (not a maze).

    Raises:
        CorruptDatasetError: Some of them but not all.
    """
    if a.positions is None and a.layouts is None and a.layout_indices is None:
        return None
    if a.positions is None or a.layouts is None or a.layout_indices is None:
        raise CorruptDatasetError(f"{path}: maze positions, layouts and layout indices come"
                                  " together, but some of them are missing")
    return MazeColumns(a.positions, a.layouts, a.layout_indices)


def _check_maze(m: MazeColumns, path: object) -> None:
    n = m.layouts.shape[1] if m.layouts.ndim == 3 else -1
    if m.layouts.ndim != 3 or m.layouts.shape[2] != n or np.any(m.layouts > MAZE_CELL_BITS):
        raise CorruptDatasetError(f"{path}: maze layouts are not grids of cell bits")
    if m.positions.ndim != 2 or m.positions.shape[1] != 2 or np.any(m.positions < 0) \
            or np.any(m.positions >= n):
        raise CorruptDatasetError(f"{path}: agent positions lie outside the {n}x{n} maze")
    if np.any(m.layout_indices < 0):
        raise CorruptDatasetError(f"{path}: negative maze layout index")


def check_observations(observations: np.ndarray, space: spaces.Space[Any] | None,
                       path: str | os.PathLike[str]) -> None:
    """Observations are finite and inside ``space`` (a ``Box``; None: finite only).

    Raises:
        CorruptDatasetError: A value is NaN, infinite or outside the space.
    """
    _finite(observations, "observations", path)
    if not isinstance(space, spaces.Box) or not observations.size:
        return
    if observations.dtype.kind in "ui":
        limits = np.iinfo(observations.dtype)
        if np.all(space.low <= limits.min) and np.all(space.high >= limits.max):
            return  # every value of the dtype is inside (uint8 images)
    # Per-feature extremes: no temporary as big as the observations.
    if np.any(observations.min(axis=0) < space.low) \
            or np.any(observations.max(axis=0) > space.high):
        raise CorruptDatasetError(f"{path}: observations outside the observation space")


def check_values(a: DatasetArrays, *, action_count: int, path: str | os.PathLike[str],
                 observation_space: spaces.Space[Any] | None = None) -> None:
    """Check the value rules of the module docstring on the arrays of a file or an episode.

    Args:
        a: The arrays (an episode's: offsets relative to the episode).
        action_count: ``n`` of the ``Discrete(n)`` action space.
        path: The file, for messages.
        observation_space: The space the observations must lie in, if known.

    Raises:
        CorruptDatasetError: A rule is broken; the message names the file and the rule.
    """
    for name in ("rewards", "episode_returns"):
        _finite(getattr(a, name), name.replace("episode_", "episode "), path)
    check_observations(a.observations, observation_space, path)
    for name in ("actions", "idm_eval_actions"):
        actions = getattr(a, name)
        if actions is not None and len(actions) and (
                actions.min() < 0 or actions.max() >= action_count):
            raise CorruptDatasetError(f"{path}: {name} outside the action space"
                                      f" Discrete({action_count})")
    _check_episode_ends(a, path)
    maze = maze_columns(a, path)
    if maze is not None:
        _check_maze(maze, path)
