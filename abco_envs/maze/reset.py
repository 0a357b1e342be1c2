"""What a maze reset draws: its layout, from the ``layout`` option, the pool or the generator.

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
from abco_envs.maze.layout import generate_layout, layout_hash, validate_layout
from abco_envs.maze.options import check_layout_index
from abco_envs.maze.pool import LOOP_FRACTION, layout_pool
from abco_envs.maze.rules import move_table

__all__ = ["DrawnLayout", "LayoutSource"]


class DrawnLayout(NamedTuple):
    """One reset's layout.

    Attributes:
        cells: The ``(n, n)`` layout (read-only when it comes from the pool).
        index: Its index in the split, or -1 for an explicit or procedural layout.
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
        split: ``"train"`` or ``"test"`` (the canonical pool's split), or ``"procedural"``.

    Attributes:
        layouts: The split's ``(k, n, n)`` layouts; ``None`` for ``"procedural"``.
        ids: Their structural ids; ``None`` for ``"procedural"``.
    """

    def __init__(self, size: int, split: str) -> None:
        self.size, self.split = size, split
        self.layouts: np.ndarray | None = None
        self.ids: tuple[str, ...] | None = None
        if split != "procedural":
            pool = layout_pool(size)
            self.layouts, self.ids = pool.split(split), pool.ids(split)
            self._moves = _pool_move_tables(size, split)

    def draw(self, rng: np.random.Generator, layout: Any = None, index: Any = None) -> DrawnLayout:
        """The layout of one reset; ``rng`` is drawn from only when no option fixes it.

        Args:
            rng: The env's generator (procedural layouts, or a random index into the split).
            layout: The ``layout`` reset option (validated), if given.
            index: The ``layout_index`` reset option, if given (ignored with ``layout``).

        Raises:
            InvalidLayoutError: ``layout`` is not a valid layout of this size.
            InvalidOptionError: ``index`` is not an integer, or is given to a procedural env.
            OptionOutOfRangeError: ``index`` is outside the split (an ``IndexError``).
        """
        if layout is not None:
            cells = validate_layout(layout, self.size)
            return DrawnLayout(cells, -1, layout_hash(cells), move_table(cells))
        if self.layouts is None or self.ids is None:
            if index is not None:
                raise InvalidOptionError(
                    f"reset option 'layout_index' {index!r} needs a pool split, but this env's"
                    " split is 'procedural' (its layouts are generated, not indexed)"
                )
            cells = generate_layout(self.size, rng, LOOP_FRACTION)
            return DrawnLayout(cells, -1, layout_hash(cells), move_table(cells))
        if index is None:
            index = int(rng.integers(len(self.layouts)))
        else:
            index = check_layout_index(index, len(self.layouts), self.split)
        return DrawnLayout(self.layouts[index], index, self.ids[index], self._moves[index])
