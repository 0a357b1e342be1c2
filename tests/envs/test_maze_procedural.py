"""The procedural split and fresh layouts: disjoint from the pool and from each other,
deterministic, and what the envs (single and vector) play with ``split=``."""

import gymnasium as gym
import numpy as np
import pytest

import abco_envs
import abco_envs.maze.reset
from abco_envs import InvalidOptionError, OptionOutOfRangeError, layout_pool
from abco_envs.maze.layout import layout_hash, validate_layout
from abco_envs.maze.procedural import (
    PROCEDURAL_SPLIT_SIZE,
    draw_fresh_layout,
    fresh_layouts,
    layout_family,
    procedural_ids,
    procedural_layouts,
)


def _pool_ids(n: int) -> set[str]:
    pool = layout_pool(n)
    return set(pool.train_ids) | set(pool.test_ids)


@pytest.mark.parametrize(("n", "count"), [(5, 300), (10, 60)])
def test_procedural_layouts_are_distinct_valid_and_outside_the_pool(n, count):
    layouts = procedural_layouts(n, count)
    ids = procedural_ids(n, count)
    assert layouts.shape == (count, n, n) and layouts.dtype == np.uint8
    assert not layouts.flags.writeable
    assert [layout_hash(c) for c in layouts] == list(ids)
    assert len(set(ids)) == count
    assert set(ids).isdisjoint(layout_pool(n).test_ids)  # the held-out split, by hash
    assert set(ids).isdisjoint(layout_pool(n).train_ids)
    assert {layout_family(i) for i in ids} == {"procedural"}
    for cells in layouts[:20]:
        validate_layout(cells, n)


def test_procedural_prefix_does_not_depend_on_the_count():
    assert procedural_ids(5, 7) == procedural_ids(5, 40)[:7]
    assert np.array_equal(procedural_layouts(5, 7), procedural_layouts(5, 40)[:7])


def test_procedural_split_is_pinned():
    # The order is a contract (the procedural datasets play layout k of it): pinned here.
    assert procedural_ids(5, 2) == ("5x5-0409b2272536", "5x5-bfecd0b73958")
    assert procedural_ids(10, 2) == ("10x10-3032a7715ee2", "10x10-277dcf841752")


@pytest.mark.parametrize("n", [3, 5, 10])
def test_fresh_layouts_are_disjoint_from_everything(n):
    fresh = fresh_layouts(n, 40, seed=123)
    ids = [layout_hash(c) for c in fresh]
    assert {layout_family(i) for i in ids} == {"fresh"}
    assert _pool_ids(n).isdisjoint(ids)
    if n > 3:  # 3x3 has no procedural split; the parity keeps the two apart at any count
        assert set(procedural_ids(n, 300)).isdisjoint(ids)
        assert len(set(ids)) == 40
    for cells in fresh:
        validate_layout(cells, n)


def test_fresh_layouts_are_seeded():
    assert np.array_equal(fresh_layouts(5, 5, seed=7), fresh_layouts(5, 5, seed=7))
    assert np.array_equal(fresh_layouts(5, 5, seed=7)[1:], fresh_layouts(5, 4, seed=8))
    assert not np.array_equal(fresh_layouts(5, 5, seed=7), fresh_layouts(5, 5, seed=9))
    a, _ = draw_fresh_layout(5, np.random.default_rng(3))
    b, _ = draw_fresh_layout(5, np.random.default_rng(3))
    assert np.array_equal(a, b)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: fresh_layouts(2, 1), "fresh layouts need an integer maze size of at least 3"),
        (lambda: fresh_layouts(5, -1), "count must be a non-negative integer"),
        (lambda: fresh_layouts(5, 1, seed=-2), "seed must be a non-negative integer"),
        (lambda: procedural_layouts(5, 2.0), "count must be a non-negative integer"),
        (lambda: procedural_layouts(3, 10_000), "distinct procedural 3x3 layouts"),
    ],
)
def test_bad_arguments_are_named(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.fixture
def small_procedural_split(monkeypatch):
    """A procedural split of 50 layouts, so random draws need not generate 10,000."""
    monkeypatch.setattr(abco_envs.maze.reset, "PROCEDURAL_SPLIT_SIZE", 50)
    return 50


def test_procedural_env_plays_the_split_by_index():
    env = gym.make("AbcoMaze5x5-v0", split="procedural")
    _, info = env.reset(seed=0, options={"layout_index": 12})
    assert info["layout_index"] == 12 and info["layout_id"] == procedural_ids(5, 13)[12]
    assert np.array_equal(env.unwrapped.cells, procedural_layouts(5, 13)[12])
    with pytest.raises(OptionOutOfRangeError, match="of 10000 layouts"):
        env.reset(options={"layout_index": PROCEDURAL_SPLIT_SIZE})


def test_procedural_env_draws_an_index_from_its_seed(small_procedural_split):
    env = gym.make("AbcoMaze5x5-v0", split="procedural")
    _, a = env.reset(seed=4)
    _, b = env.reset(seed=4)
    assert a["layout_id"] == b["layout_id"] and 0 <= a["layout_index"] < small_procedural_split
    assert a["layout_id"] == procedural_ids(5, a["layout_index"] + 1)[-1]
    assert len({env.reset(seed=s)[1]["layout_index"] for s in range(20)}) > 5


def test_fresh_env_draws_fresh_layouts_from_its_seed():
    env = gym.make("AbcoMaze10x10-v0", split="fresh")
    _, info = env.reset(seed=31)
    assert info["layout_index"] == -1
    assert np.array_equal(env.unwrapped.cells, fresh_layouts(10, 1, seed=31)[0])
    _, again = env.reset(seed=31)
    assert again["layout_id"] == info["layout_id"]
    with pytest.raises(InvalidOptionError, match="needs an indexed split"):
        env.reset(seed=0, options={"layout_index": 3})


def test_vector_env_slots_are_the_fresh_layouts_of_their_seeds():
    envs = gym.make_vec(
        "AbcoMaze5x5-v0", num_envs=4, split="fresh", vectorization_mode="vector_entry_point"
    )
    _, info = envs.reset(seed=50)
    assert np.array_equal(envs.unwrapped.cells, fresh_layouts(5, 4, seed=50))
    assert info["layout_index"].tolist() == [-1] * 4


@pytest.mark.parametrize(
    ("split", "options"), [("fresh", None), ("procedural", {"layout_index": [3, 1, 4, 1]})]
)
def test_vector_env_equals_sync_on_the_new_splits(split, options, small_procedural_split):
    kwargs = {"num_envs": 4, "max_episode_steps": 15, "split": split}
    sync = gym.make_vec("AbcoMaze5x5-v0", vectorization_mode="sync", **kwargs)
    native = gym.make_vec("AbcoMaze5x5-v0", vectorization_mode="vector_entry_point", **kwargs)
    if options is not None:  # SyncVectorEnv passes one options dict to every env
        oa = np.stack(
            [
                sync.envs[i].reset(seed=9 + i, options={"layout_index": k})[0]
                for i, k in enumerate(options["layout_index"])
            ]
        )
    else:
        oa, _ = sync.reset(seed=9)
    ob, _ = native.reset(seed=9, options=options)
    assert np.array_equal(oa, ob)
    rng = np.random.default_rng(0)
    for _ in range(60):  # autoresets draw the next fresh layouts from each slot's generator
        actions = rng.integers(4, size=4)
        a, b = sync.step(actions), native.step(actions)
        for x, y in zip(a[:4], b[:4]):
            assert np.array_equal(x, y)
        assert np.array_equal(a[4]["layout_id"], b[4]["layout_id"])


@pytest.mark.parametrize(("env_id", "split", "least"), [("AbcoMaze3x3-v0", "procedural", 4)])
def test_small_grids_refuse_the_new_splits(env_id, split, least):
    with pytest.raises(InvalidOptionError, match=f"needs a maze of at least {least}x{least}"):
        gym.make(env_id, split=split)
    with pytest.raises(InvalidOptionError, match="needs a maze of at least 3x3"):
        abco_envs.MazeEnv(size=2, split="fresh")
    with pytest.raises(InvalidOptionError, match="unknown split 'fresh-ish'"):
        abco_envs.MazeEnv(size=5, split="fresh-ish")
