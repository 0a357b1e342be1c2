"""A dataset's data in memory: :class:`Episode` (one episode), :class:`DatasetArrays` (every
column) and :class:`MazeFrames` (maze frames kept as the layout and agent cell that draw
them). Plain records of numpy arrays, made by :class:`abco_data.Dataset`'s readers and
checked by :func:`abco_data.format.validation.check_values`; this module imports no other part of
abco_data (the maze renderer comes from abco_envs).

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

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import DTypeLike

from abco_envs.maze.render import MazeRenderer

__all__ = ["Episode", "DatasetArrays", "MazeFrames"]

#: Frames drawn per step of a whole-column pass (:meth:`MazeFrames.first_difference`,
#: ``np.asarray``): about 25 MB of 64x64 frames at a time.
_BLOCK_ROWS = 2048


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


@dataclass(frozen=True, eq=False)
class MazeFrames:
    """A maze dataset's RGB frames, kept as what draws them and drawn when indexed.

    A maze frame is its layout's background (floor, walls, start and goal) plus the agent's
    dot in its cell (:class:`abco_envs.maze.render.MazeRenderer`), so a column of frames is
    one background per distinct layout and, per row, the background's number and the agent's
    cell: a few bytes a frame instead of 12 KiB at 64x64. Indexing draws the rows asked for,
    byte for byte the frames the renderer draws (``frames[rows]`` is what ``observations[rows]``
    of the decoded column is, when :meth:`first_difference` finds none). It reads like that
    ``(N, H, W, 3)`` uint8 array: ``shape``, ``dtype``, ``len``, integer, slice and index-array
    indexing, and ``np.asarray`` (which draws every row: the memory this saves).

    Attributes:
        backgrounds: ``(L, H, W, 3)`` uint8, one per distinct layout (may be shared).
        background_of_row: ``(N,)`` the background of each row.
        cell_of_row: ``(N,)`` the agent's cell ``row * n + col`` in each row.
        dot_bytes: ``(n * n, D)`` byte offsets of the agent's dot in a frame, per cell.
        dot_colour: ``(D,)`` the bytes written there.

    Example:
        >>> cells = np.full((1, 3, 3), 15, np.uint8)  # one 3x3 layout without inner walls
        >>> frames, = MazeFrames.draw_columns([(cells, np.array([2]), np.array([[0, 0],
        ...     [0, 1], [1, 1]]))], height=12, width=12)
        >>> frames.shape, len(frames), frames.dtype
        ((3, 12, 12, 3), 3, dtype('uint8'))
        >>> r = MazeRenderer(3, 12, 12)
        >>> bool(np.array_equal(frames[1], r.frame(cells[0], 0, 1)))
        True
        >>> frames.first_difference(lambda a, b: np.asarray(frames)[a:b]) is None
        True
    """

    backgrounds: np.ndarray
    background_of_row: np.ndarray
    cell_of_row: np.ndarray
    dot_bytes: np.ndarray
    dot_colour: np.ndarray

    @classmethod
    def draw_columns(cls, columns: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], *,
                     height: int, width: int) -> list[MazeFrames]:
        """The frames of several maze columns, sharing one background per distinct layout.

        Args:
            columns: Per column, its episodes' ``(E, n, n)`` layouts, their ``(E,)`` lengths
                ``T`` (each episode holds ``T + 1`` rows, episodes one after the other), and
                the ``(N, 2)`` agent positions of its rows.
            height: Frame height in pixels.
            width: Frame width in pixels.

        Raises:
            ValueError: The columns disagree on the maze size, a column's positions are not
                one row per observation, or the frame is too small for the maze.
        """
        layouts = [np.asarray(c[0], dtype=np.uint8) for c in columns]
        sizes = {x.shape[1:] for x in layouts}
        if len(sizes) != 1 or len(next(iter(sizes))) != 2:
            raise ValueError(f"maze columns of layouts shaped {sorted(sizes)}: one n x n size"
                             " expected")
        n = next(iter(sizes))[0]
        renderer = MazeRenderer(n, height, width)
        every = np.concatenate([x.reshape(len(x), -1) for x in layouts])
        distinct, which = np.unique(every, axis=0, return_inverse=True)
        backgrounds = np.empty((len(distinct), height, width, 3), dtype=np.uint8)
        for i, cells in enumerate(distinct):
            backgrounds[i] = renderer.background(cells.reshape(n, n))
        frames, first = [], 0
        for (_, lengths, positions), x in zip(columns, layouts):
            lengths, positions = np.asarray(lengths, np.int64), np.asarray(positions, np.int64)
            mine = which.reshape(-1)[first : first + len(x)]
            first += len(x)
            rows = int((lengths + 1).sum())
            if positions.shape != (rows, 2):
                raise ValueError(f"{len(positions)} agent positions for {rows} maze frames")
            frames.append(cls(
                backgrounds=backgrounds,
                background_of_row=np.repeat(mine, lengths + 1).astype(np.int32),
                cell_of_row=(positions[:, 0] * n + positions[:, 1]).astype(np.int32),
                dot_bytes=renderer.dot_bytes, dot_colour=renderer.dot_colour))  # fmt: skip
        return frames

    @property
    def shape(self) -> tuple[int, ...]:
        """``(N, H, W, 3)``, as the decoded column's."""
        return (len(self.background_of_row), *self.backgrounds.shape[1:])

    @property
    def dtype(self) -> np.dtype[Any]:
        """``uint8``."""
        return self.backgrounds.dtype

    @property
    def ndim(self) -> int:
        """4."""
        return self.backgrounds.ndim

    @property
    def nbytes(self) -> int:
        """Bytes held: the backgrounds (shared ones too), the per-row numbers, the dot tables."""
        return sum(v.nbytes for v in vars(self).values())

    def __len__(self) -> int:
        return len(self.background_of_row)

    def __getitem__(self, key: Any) -> np.ndarray:
        """The frames of rows ``key``: an int, a slice, or an integer (or boolean) array."""
        if isinstance(key, tuple):
            raise TypeError("MazeFrames takes one index (rows), not a tuple: index the drawn"
                            " frames for the rest")  # fmt: skip
        if isinstance(key, slice):
            key = np.arange(*key.indices(len(self)))
        rows = np.asarray(key)
        if rows.dtype.kind not in "iub":
            raise IndexError(f"maze frames are indexed by integers, not {rows.dtype}")
        if rows.ndim == 0:
            return self._draw(rows.reshape(1))[0]
        return self._draw(rows)

    def _draw(self, rows: np.ndarray) -> np.ndarray:
        """Frames of an index array: the backgrounds gathered, then each agent's dot."""
        out = np.take(self.backgrounds, self.background_of_row[rows], axis=0)
        if out.size:
            flat = out.reshape(len(out), -1)
            flat[np.arange(len(out))[:, None], self.dot_bytes[self.cell_of_row[rows]]] = (
                self.dot_colour)
        return out

    def __array__(self, dtype: DTypeLike | None = None, copy: bool | None = None
                  ) -> np.ndarray:  # fmt: skip
        """Every frame, drawn into one array (the whole decoded column's memory)."""
        out = np.empty(self.shape, dtype=self.dtype)
        for start in range(0, len(self), _BLOCK_ROWS):
            out[start : start + _BLOCK_ROWS] = self[start : start + _BLOCK_ROWS]
        return out if dtype is None else out.astype(dtype, copy=False)

    def astype(self, dtype: DTypeLike) -> np.ndarray:
        """Every frame as an array of ``dtype`` (``np.asarray(frames).astype(dtype)``)."""
        return np.asarray(self).astype(dtype, copy=False)

    def first_difference(self, read: Callable[[int, int], np.ndarray]) -> int | None:
        """The first row whose drawn frame differs from ``read(start, stop)``'s, or None.

        ``read`` gives rows ``start:stop`` of the column these frames stand for (the file's,
        decoded); they are compared a block at a time, so the check holds one block of each.
        """
        for start in range(0, len(self), _BLOCK_ROWS):
            stop = min(start + _BLOCK_ROWS, len(self))
            stored, drawn = read(start, stop), self[start:stop]
            if stored.shape != drawn.shape:
                return start
            same = (stored == drawn).reshape(len(drawn), -1).all(axis=1)
            if not same.all():
                return start + int(np.argmin(same))
        return None
