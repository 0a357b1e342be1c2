"""Layouts: generator, validation, hashing and the canonical pool."""

import numpy as np
import pytest

from abco_envs import MAZE_SIZES
from abco_envs.maze.layout import (
    InvalidLayoutError,
    count_passages,
    distances_to,
    generate_layout,
    layout_hash,
    shortest_path_length,
    validate_layout,
)
from abco_envs.maze.pool import SPLIT_SIZE, layout_pool


@pytest.mark.parametrize("n", [2, 3, 5, 10, 17])
@pytest.mark.parametrize("seed", range(20))
def test_perfect_maze_is_a_spanning_tree(n, seed):
    cells = generate_layout(n, np.random.default_rng(seed), loop_fraction=0.0)
    assert count_passages(cells) == n * n - 1
    validate_layout(cells)  # connected and consistent


@pytest.mark.parametrize("n", MAZE_SIZES)
def test_loops_add_passages(n):
    cells = generate_layout(n, np.random.default_rng(0), loop_fraction=0.2)
    assert count_passages(cells) > n * n - 1
    validate_layout(cells)


def test_same_seed_same_layout_and_hash():
    a = generate_layout(5, np.random.default_rng(7))
    b = generate_layout(5, np.random.default_rng(7))
    c = generate_layout(5, np.random.default_rng(8))
    assert np.array_equal(a, b) and layout_hash(a) == layout_hash(b)
    assert layout_hash(a) != layout_hash(c)


@pytest.mark.parametrize("n", MAZE_SIZES)
def test_pool_splits_are_disjoint_distinct_and_stable(n):
    pool = layout_pool(n)
    assert len(pool.train) == len(pool.test) == SPLIT_SIZE
    ids = pool.train_ids + pool.test_ids
    assert len(set(ids)) == len(ids)
    assert [layout_hash(c) for c in pool.train] == list(pool.train_ids)
    for cells in np.concatenate([pool.train, pool.test]):
        validate_layout(cells, n)
    with pytest.raises(ValueError):
        pool.train[0, 0, 0] = 0  # the canonical pool is read-only


def test_pool_shortest_paths_match_the_papers_mazes():
    # reference.md: gym-maze sample means 4.04 (3x3), 8.24 (5x5), 19.14 (10x10).
    for n, expected in ((3, 4.04), (5, 8.24), (10, 19.14)):
        mean = np.mean([shortest_path_length(c) for c in layout_pool(n).train])
        assert abs(mean - expected) < 0.1 * expected


def _open_corridor(n):
    """A serpentine perfect maze built by hand."""
    cells = np.zeros((n, n), dtype=np.uint8)
    for r in range(n):
        for c in range(n - 1):
            cells[r, c] |= 2
            cells[r, c + 1] |= 8
    for r in range(n - 1):
        c = n - 1 if r % 2 == 0 else 0
        cells[r, c] |= 4
        cells[r + 1, c] |= 1
    return cells


def test_validate_accepts_a_hand_made_maze():
    cells = _open_corridor(4)
    assert count_passages(cells) == 15
    assert distances_to(cells, (0, 0)).max() == 15


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda c: c.__setitem__((0, 0), c[0, 0] | 1), "outside"),
        (lambda c: c.__setitem__((1, 1), c[1, 1] ^ 2), "inconsistent"),
        (lambda c: c.__setitem__((2, 2), 16), "0..15"),
        (lambda c: None, None),
    ],
)
def test_validate_rejects_bad_layouts(mutate, message):
    cells = _open_corridor(4)
    mutate(cells)
    if message is None:
        validate_layout(cells)
        return
    with pytest.raises(InvalidLayoutError, match=message):
        validate_layout(cells)


def test_validate_rejects_disconnected_and_misshapen():
    cells = _open_corridor(3)
    cells[2, 1] &= ~np.uint8(2)  # cut the last corridor: cell (2, 2) is sealed off
    cells[2, 2] &= ~np.uint8(8)
    with pytest.raises(InvalidLayoutError, match="disconnected"):
        validate_layout(cells)
    with pytest.raises(InvalidLayoutError, match="square"):
        validate_layout(np.zeros((3, 4), dtype=int))
    with pytest.raises(InvalidLayoutError, match="integers"):
        validate_layout(np.zeros((3, 3), dtype=float))
    with pytest.raises(InvalidLayoutError, match="expected a 5x5"):
        validate_layout(_open_corridor(3), n=5)
