"""A dataset's data in memory: :class:`Episode` (one episode) and :class:`DatasetArrays` (every
column). Plain records of numpy arrays, made by :class:`abco_data.Dataset`'s readers and
checked by :func:`abco_data.validation.check_values`; this module imports no other part of
abco_data.

Example:
    >>> import numpy as np
    >>> ep = Episode(index=0, seed=7, observations=np.zeros((3, 4), np.float32),
    ...     actions=None, rewards=np.ones(2), terminations=np.array([False, True]),
    ...     truncations=np.zeros(2, bool), episode_return=2.0)
    >>> a = DatasetArrays.of_episode(ep)
    >>> ep.length, a.episode_lengths.tolist(), a.episode_returns.tolist()
    (2, [2], [2.0])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Episode", "DatasetArrays"]


@dataclass(frozen=True, eq=False)
class Episode:
    """One episode: ``T + 1`` observations and ``T`` of everything else.

    ``actions`` is ``None`` for expert data (whose actions are kept apart, for measuring IDM
    accuracy only). ``layout``, ``layout_index`` and ``positions`` are ``None`` outside mazes.
    """

    index: int
    seed: int
    observations: np.ndarray
    actions: np.ndarray | None
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    episode_return: float
    layout: np.ndarray | None = None
    layout_index: int | None = None
    positions: np.ndarray | None = None

    @property
    def length(self) -> int:
        """Number of transitions ``T``."""
        return len(self.rewards)


@dataclass(frozen=True, eq=False)
class DatasetArrays:
    """Every column of a dataset in memory (see ``docs/format.md`` for each one).

    ``actions`` is set for pre-demonstrations, ``idm_eval_actions`` for expert data (never
    for training). Maze-only columns are ``None`` elsewhere.
    """

    observations: np.ndarray
    actions: np.ndarray | None
    idm_eval_actions: np.ndarray | None
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    episode_starts: np.ndarray
    episode_transition_starts: np.ndarray
    episode_lengths: np.ndarray
    episode_seeds: np.ndarray
    episode_returns: np.ndarray
    positions: np.ndarray | None = None
    layouts: np.ndarray | None = None
    layout_indices: np.ndarray | None = None

    @property
    def nbytes(self) -> int:
        """Total bytes of the arrays."""
        return sum(v.nbytes for v in vars(self).values() if isinstance(v, np.ndarray))

    @classmethod
    def of_episode(cls, ep: Episode) -> DatasetArrays:
        """The arrays of one episode, offsets relative to it (``idm_eval_actions`` None)."""
        first = np.zeros(1, dtype=np.int64)
        return cls(
            observations=ep.observations, actions=ep.actions, idm_eval_actions=None,
            rewards=ep.rewards, terminations=ep.terminations, truncations=ep.truncations,
            episode_starts=first, episode_transition_starts=first,
            episode_lengths=np.array([ep.length]), episode_seeds=np.array([ep.seed]),
            episode_returns=np.array([ep.episode_return]), positions=ep.positions,
            layouts=None if ep.layout is None else ep.layout[None],
            layout_indices=None if ep.layout_index is None else np.array([ep.layout_index]))
