"""Layouts beyond the canonical pool: the ``procedural`` split and ``fresh`` layouts.

Both come from :func:`~abco_envs.maze.layout.generate_layout` (the pool's generator, same
loop fraction) and both are disjoint, by structural id (:func:`layout_hash`), from the
canonical pool's ``train`` and ``test`` splits and from each other:

- the ``procedural`` split of a size is the first :data:`PROCEDURAL_SPLIT_SIZE` structurally
  distinct layouts of one fixed seeded stream whose id ends in an even hex digit, leaving out
  the pool's 200. Its order is part of the contract, like the pool's: the procedural datasets
  play layout ``k`` of it, and its first ``K`` layouts are the same whatever count is asked
  for (:func:`procedural_layouts`), which is what taking the first ``K`` layouts of a dataset
  relies on.
- a ``fresh`` layout is drawn from any generator (an env's ``np_random``): draws are repeated
  until one has an id ending in an odd hex digit that is not in the pool. No dataset is made
  from fresh layouts, so they are never in any dataset: an evaluation on them measures
  generalisation to unseen mazes.

The parity of the id is what keeps the two apart: a fresh draw needs no list of procedural
layouts to check against, and stays disjoint from the procedural split however many
procedural layouts are ever made. Half of all draws are rejected by each stream, which is the
price (a 10x10 layout takes about 1.2 ms to draw, 5x5 about 0.3 ms).

Small grids have few layouts: a 2x2 maze has none outside its pool and a 3x3 one a few dozen,
so the envs refuse ``split="procedural"`` below :data:`MIN_PROCEDURAL_SIZE` cells a side and
``split="fresh"`` below :data:`MIN_FRESH_SIZE`.

Example:
    >>> from abco_envs.maze.pool import layout_pool
    >>> ids = procedural_ids(5, 20)
    >>> ids[:5] == procedural_ids(5, 5)  # a prefix does not depend on the count
    True
    >>> pool = layout_pool(5)
    >>> set(ids).isdisjoint(pool.train_ids + pool.test_ids)
    True
    >>> fresh = fresh_layouts(5, 3, seed=0)
    >>> fresh.shape, [layout_family(layout_hash(c)) for c in fresh]
    ((3, 5, 5), ['fresh', 'fresh', 'fresh'])
"""

from __future__ import annotations

from functools import cache

import numpy as np
from gymnasium.utils import seeding

from abco_envs.maze.layout import InvalidLayoutError, generate_layout, layout_hash
from abco_envs.maze.pool import LOOP_FRACTION, POOL_SEED, layout_pool

__all__ = [
    "PROCEDURAL_SPLIT_SIZE",
    "MIN_PROCEDURAL_SIZE",
    "MIN_FRESH_SIZE",
    "layout_family",
    "procedural_layouts",
    "procedural_ids",
    "procedural_layout",
    "draw_fresh_layout",
    "fresh_layouts",
]

#: Layouts in the ``procedural`` split of each size (what the procedural datasets can use).
PROCEDURAL_SPLIT_SIZE = 10_000
#: Smallest maze with a ``procedural`` split: a 3x3 grid has only a few dozen layouts left.
MIN_PROCEDURAL_SIZE = 4
#: Smallest maze with ``fresh`` layouts: every 2x2 layout is in the 2x2 pool.
MIN_FRESH_SIZE = 3
#: Give up after this many draws in a row bring no new layout (only tiny grids run out of
#: layouts: on 4x4 and larger about every second draw is new, so 2,000 misses in a row do not
#: happen, and a 3x3 grid fails in a fraction of a second instead of after millions of draws).
_MAX_MISSES = 2_000
#: The procedural stream's seed, after the pool's ``[POOL_SEED, size]``: its own stream.
_PROCEDURAL_STREAM = 1


def layout_family(layout_id: str) -> str:
    """``"procedural"`` or ``"fresh"``: which stream may hold the layout of ``layout_id``.

    Decided by the parity of the id's last hex digit; a pool layout may have either parity
    (both streams leave the pool out by id).

    Example:
        >>> layout_family("5x5-00000000000a"), layout_family("5x5-00000000000b")
        ('procedural', 'fresh')
    """
    return "procedural" if int(layout_id[-1], 16) % 2 == 0 else "fresh"


@cache
def _pool_ids(size: int) -> frozenset[str]:
    pool = layout_pool(size)
    return frozenset(pool.train_ids + pool.test_ids)


class _ProceduralStream:
    """The procedural split of one size, generated as far as anyone has asked (per process).

    Layouts are kept read-only in a list that only grows, so layout ``k`` never changes.
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self.rng = np.random.default_rng([POOL_SEED, size, _PROCEDURAL_STREAM])
        self.layouts: list[np.ndarray] = []
        self.ids: list[str] = []
        self.seen: set[str] = set(_pool_ids(size))
        self.draws = 0
        self.misses = 0  # draws since the last new layout

    def extend(self, count: int) -> None:
        """Generate until the first ``count`` layouts exist.

        Raises:
            InvalidLayoutError: The grid has fewer procedural layouts than that.
        """
        while len(self.layouts) < count:
            if self.misses >= _MAX_MISSES:
                raise InvalidLayoutError(
                    f"only {len(self.layouts)} distinct procedural {self.size}x{self.size}"
                    f" layouts were found in {self.draws} draws, {count} were asked for"
                )
            cells = generate_layout(self.size, self.rng, LOOP_FRACTION)
            self.draws += 1
            self.misses += 1
            key = layout_hash(cells)
            if key not in self.seen and layout_family(key) == "procedural":
                self.seen.add(key)
                cells.flags.writeable = False
                self.layouts.append(cells)
                self.ids.append(key)
                self.misses = 0


@cache
def _stream(size: int) -> _ProceduralStream:
    return _ProceduralStream(size)


def _check_count(count: object, what: str) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 0:
        raise ValueError(f"{what} must be a non-negative integer, got {count!r}")
    return int(count)


def _check_size(size: object, least: int, what: str) -> int:
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < least:
        raise ValueError(
            f"{what} layouts need an integer maze size of at least {least}, got size={size!r}"
        )
    return int(size)


def procedural_layouts(size: int, count: int) -> np.ndarray:
    """The first ``count`` layouts of the ``size`` x ``size`` procedural split.

    Args:
        size: Cells per side.
        count: How many (any number; the split proper has :data:`PROCEDURAL_SPLIT_SIZE`).

    Returns:
        A ``(count, size, size)`` uint8 array (read-only); ``procedural_layouts(n, k)`` is the
        first ``k`` rows of ``procedural_layouts(n, m)`` for any ``m >= k``.

    Raises:
        ValueError: A size below 2 or a negative count.
        InvalidLayoutError: The grid has fewer procedural layouts than ``count``.
    """
    size, count = _check_size(size, 2, "procedural"), _check_count(count, "count")
    stream = _stream(size)
    stream.extend(count)
    out = np.stack(stream.layouts[:count]) if count else np.zeros((0, size, size), np.uint8)
    out.flags.writeable = False
    return out


def procedural_ids(size: int, count: int) -> tuple[str, ...]:
    """Structural ids of :func:`procedural_layouts` ``(size, count)``, in order."""
    size, count = _check_size(size, 2, "procedural"), _check_count(count, "count")
    stream = _stream(size)
    stream.extend(count)
    return tuple(stream.ids[:count])


def procedural_layout(size: int, index: int) -> tuple[np.ndarray, str]:
    """Layout ``index`` of the procedural split (read-only) and its structural id.

    Raises:
        ValueError: A size below 2 or a negative index.
        InvalidLayoutError: The grid has fewer procedural layouts than ``index + 1``.
    """
    size, index = _check_size(size, 2, "procedural"), _check_count(index, "index")
    stream = _stream(size)
    stream.extend(index + 1)
    return stream.layouts[index], stream.ids[index]


def draw_fresh_layout(size: int, rng: np.random.Generator) -> tuple[np.ndarray, str]:
    """A fresh layout drawn from ``rng``, and its structural id.

    Draws layouts until one is of the fresh family and outside the pool (see the module
    docstring), so the layout is in neither pool split, nor in the procedural split, nor in
    any dataset. Everything it draws comes from ``rng``.

    Raises:
        ValueError: A grid below :data:`MIN_FRESH_SIZE` (every 2x2 layout is in its pool).
        InvalidLayoutError: No fresh layout in 2,000 draws (never seen on 3x3 or larger).
    """
    size = _check_size(size, MIN_FRESH_SIZE, "fresh")
    pool = _pool_ids(size)
    for _ in range(_MAX_MISSES):
        cells = generate_layout(size, rng, LOOP_FRACTION)
        key = layout_hash(cells)
        if layout_family(key) == "fresh" and key not in pool:
            return cells, key
    raise InvalidLayoutError(
        f"no fresh {size}x{size} layout in {_MAX_MISSES}"
        " draws: the grid has (almost) no layouts outside its pool"
    )


def fresh_layouts(size: int, count: int, seed: int = 0) -> np.ndarray:
    """``count`` fresh layouts: layout ``i`` is the one ``reset(seed=seed + i)`` gives.

    That is, layout ``i`` is what a ``split="fresh"`` env (or slot ``i`` of a vector env
    reset with ``seed``) draws, from a generator seeded as Gymnasium seeds ``np_random``.
    Different seeds may give the same layout (on a 3x3 grid often, on 5x5 and larger almost
    never); pass them as the ``layout`` reset option to evaluate on a fixed set.

    Args:
        size: Cells per side (at least :data:`MIN_FRESH_SIZE`).
        count: How many.
        seed: Seed of the first one.

    Returns:
        A ``(count, size, size)`` uint8 array.

    Raises:
        ValueError: A size below :data:`MIN_FRESH_SIZE`, a negative count or a bad seed.
    """
    size, count = _check_size(size, MIN_FRESH_SIZE, "fresh"), _check_count(count, "count")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    out = np.zeros((count, size, size), dtype=np.uint8)
    for i in range(count):
        out[i] = draw_fresh_layout(size, seeding.np_random(int(seed) + i)[0])[0]
    return out
