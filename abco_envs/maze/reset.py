"""What a maze reset draws: its layout, from the ``layout`` option, a split or the generator.

Shared by :class:`~abco_envs.maze.env.MazeEnv` and
:class:`~abco_envs.maze.vector.MazeVectorEnv`, which is how the vector env's maze ``i`` draws
exactly what a single env seeded the same way draws.

Example:
    >>> import numpy as np
    >>> source = LayoutSource(5, "train")
    >>> drawn = source.draw(np.random.default_rng(0), index=3)
    >>> drawn.index, drawn.layout_id == source.ids[3], drawn.moves.shape
    (3, True, (25, 4))
"""

from __future__ import annotations

from functools import cache
from typing import Any, NamedTuple

import numpy as np

from abco_envs.errors import InvalidOptionError
from abco_envs.maze.layout import layout_hash, validate_layout
from abco_envs.maze.options import check_layout_index
from abco_envs.maze.pool import SPLITS, layout_pool
from abco_envs.maze.procedural import PROCEDURAL_SPLIT_SIZE, draw_fresh_layout, procedural_layout
from abco_envs.maze.rules import move_table

__all__ = ["DrawnLayout", "LayoutSource"]


class DrawnLayout(NamedTuple):
    """One reset's layout.

    Attributes:
        cells: The ``(n, n)`` layout (read-only when it comes from the pool).
        index: Its index in the split, or -1 for an explicit or fresh layout.
        layout_id: Its structural id (:func:`~abco_envs.maze.layout.layout_hash`).
        moves: Its ``(n * n, 4)`` :func:`~abco_envs.maze.rules.move_table`.
    """

    cells: np.ndarray
    index: int
    layout_id: str
    moves: np.ndarray


@cache
def _pool_move_tables(size: int, split: str) -> np.ndarray:
    """Move tables of a whole pool split, built once per process (the pool never changes)."""
    tables = move_table(layout_pool(size).split(split))
    tables.flags.writeable = False
    return tables


class LayoutSource:
    """Where the resets of a maze env take their layouts from.

    Args:
        size: Cells per side.
        split: ``"train"`` or ``"test"`` (the canonical pool's split), ``"procedural"`` (the
            procedural split, indexed like the pool's; see :mod:`abco_envs.maze.procedural`)
            or ``"fresh"`` (a fresh layout drawn at each reset, in no split).

    Attributes:
        count: Layouts in the split; ``None`` for ``"fresh"``.
        layouts: A pool split's ``(k, n, n)`` layouts; ``None`` for the other splits (the
            procedural split is generated as far as resets ask, not all at once).
        ids: Their structural ids; ``None`` likewise.
    """

    def __init__(self, size: int, split: str) -> None:
        self.size, self.split = size, split
        self.layouts: np.ndarray | None = None
        self.ids: tuple[str, ...] | None = None
        self.count: int | None = None
        if split in SPLITS:
            pool = layout_pool(size)
            self.layouts, self.ids = pool.split(split), pool.ids(split)
            self.count = len(self.layouts)
            self._moves = _pool_move_tables(size, split)
        elif split == "procedural":
            self.count = PROCEDURAL_SPLIT_SIZE

    def draw(self, rng: np.random.Generator, layout: Any = None, index: Any = None) -> DrawnLayout:
        """The layout of one reset; ``rng`` is drawn from only when no option fixes it.

        Args:
            rng: The env's generator (fresh layouts, or a random index into the split).
            layout: The ``layout`` reset option (validated), if given.
            index: The ``layout_index`` reset option, if given (ignored with ``layout``).

        Raises:
            InvalidLayoutError: ``layout`` is not a valid layout of this size.
            InvalidOptionError: ``index`` is not an integer, or is given to a fresh env.
            OptionOutOfRangeError: ``index`` is outside the split (an ``IndexError``).
        """
        if layout is not None:
            cells = validate_layout(layout, self.size)
            return DrawnLayout(cells, -1, layout_hash(cells), move_table(cells))
        if self.count is None:
            if index is not None:
                raise InvalidOptionError(
                    f"reset option 'layout_index' {index!r} needs an indexed split ('train',"
                    " 'test' or 'procedural'), but this env's split is 'fresh' (its layouts"
                    " are drawn, not indexed)"
                )
            cells, key = draw_fresh_layout(self.size, rng)
            return DrawnLayout(cells, -1, key, move_table(cells))
        if index is None:
            index = int(rng.integers(self.count))
        else:
            index = check_layout_index(index, self.count, self.split)
        if self.layouts is None or self.ids is None:  # the procedural split
            cells, key = procedural_layout(self.size, index)
            return DrawnLayout(cells, index, key, move_table(cells))
        return DrawnLayout(self.layouts[index], index, self.ids[index], self._moves[index])
