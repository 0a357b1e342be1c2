"""The canonical layout pool of each maze size, with disjoint ``train`` and ``test`` splits.

The pool is generated, never stored: one fixed seed per size drives :func:`generate_layout`
until enough structurally distinct layouts exist (deduplicated by :func:`layout_hash`, because
seeds collide: a 3x3 grid has only 192 perfect mazes). The first ``SPLIT_SIZE`` distinct ones
form ``train``, the next ``SPLIT_SIZE`` form ``test``. Datasets, experts and evaluation all
refer to layouts by split and index, so this order is part of the environments' contract.

Example:
    >>> from abco_envs.maze.pool import layout_pool
    >>> pool = layout_pool(3)
    >>> len(pool.train), len(pool.test)
    (100, 100)
    >>> set(pool.train_ids).isdisjoint(pool.test_ids)
    True
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from abco_envs.maze.layout import generate_layout, layout_hash

__all__ = ["LayoutPool", "layout_pool", "SPLITS", "SPLIT_SIZE", "LOOP_FRACTION", "POOL_SEED"]

#: Layouts in each split.
SPLIT_SIZE = 100
#: Share of cells with an extra wall removed, as in the paper's sample mazes.
LOOP_FRACTION = 0.2
#: Root of the pool seeds (the paper's year); one stream per size (and more in
#: :mod:`abco_envs.maze.procedural`).
POOL_SEED = 2020
#: Give up after this many draws per wanted layout (only tiny grids run out of layouts).
_MAX_DRAWS_PER_LAYOUT = 200
SPLITS = ("train", "test")


@dataclass(frozen=True)
class LayoutPool:
    """The canonical layouts of one maze size.

    Attributes:
        size: Cells per side.
        train: ``(k, n, n)`` uint8 layouts of the train split (read-only).
        test: ``(m, n, n)`` uint8 layouts of the test split (read-only).
        train_ids: Structural ids of ``train``, in order.
        test_ids: Structural ids of ``test``, in order.
    """

    size: int
    train: np.ndarray
    test: np.ndarray
    train_ids: tuple[str, ...]
    test_ids: tuple[str, ...]

    def split(self, name: str) -> np.ndarray:
        """The layouts of split ``name`` (``"train"`` or ``"test"``)."""
        if name not in SPLITS:
            raise ValueError(f"unknown split {name!r}; expected one of {SPLITS}")
        return self.train if name == "train" else self.test

    def ids(self, name: str) -> tuple[str, ...]:
        """The structural ids of split ``name``."""
        self.split(name)
        return self.train_ids if name == "train" else self.test_ids


@cache
def layout_pool(size: int) -> LayoutPool:
    """Build (once per process) the canonical pool of ``size`` x ``size`` mazes."""
    rng = np.random.default_rng([POOL_SEED, size])
    wanted = 2 * SPLIT_SIZE
    layouts: list[np.ndarray] = []
    ids: list[str] = []
    seen: set[str] = set()
    for _ in range(wanted * _MAX_DRAWS_PER_LAYOUT):
        cells = generate_layout(size, rng, LOOP_FRACTION)
        key = layout_hash(cells)
        if key not in seen:
            seen.add(key)
            layouts.append(cells)
            ids.append(key)
            if len(layouts) == wanted:
                break
    # With fewer distinct layouts than wanted, train keeps its full size first.
    n_train = min(SPLIT_SIZE, len(layouts))
    train = np.stack(layouts[:n_train])
    test = np.stack(layouts[n_train:]) if len(layouts) > n_train else train[:0].copy()
    for arr in (train, test):
        arr.flags.writeable = False
    return LayoutPool(size, train, test, tuple(ids[:n_train]), tuple(ids[n_train:]))
