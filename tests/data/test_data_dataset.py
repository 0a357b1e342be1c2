"""Reading a dataset: episodes, flat arrays, transitions, sampling by action, references."""

import pickle
import tracemalloc

import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_data.errors import WrongKindError


@pytest.fixture(scope="module")
def pre(tmp_path_factory):
    return abco_data.open_dataset(make_small("abco/maze5x5-pre-v0", tmp_path_factory.mktemp("p")))


@pytest.fixture(scope="module")
def expert(tmp_path_factory):
    path = make_small("abco/maze3x3-expert-v0", tmp_path_factory.mktemp("e"))
    return abco_data.open_dataset(path)


def test_fields(pre):
    assert pre.id == "abco/maze5x5-pre-v0" and pre.env_id == "AbcoMaze5x5-v0"
    assert pre.num_episodes == 8
    assert pre.observation_space.shape == (64, 64, 3) and pre.action_space.n == 4
    with pytest.raises(AttributeError):
        pre.kind = "expert"


def test_episodes_match_flat_arrays(pre):
    a = pre.load_arrays()
    assert len(a.observations) == pre.num_transitions + pre.num_episodes
    for ep in pre.episodes():
        o, t = a.episode_starts[ep.index], a.episode_transition_starts[ep.index]
        np.testing.assert_array_equal(ep.observations, a.observations[o : o + ep.length + 1])
        np.testing.assert_array_equal(ep.actions, a.actions[t : t + ep.length])
        assert ep.episode_return == pytest.approx(ep.rewards.sum())
    last = pre.episode(-1)
    assert last.index == pre.num_episodes - 1
    with pytest.raises(IndexError, match="out of range"):
        pre.episode(pre.num_episodes)


def test_transitions_never_cross_episodes(pre):
    a = pre.load_arrays()
    obs_t, obs_t1 = pre.transition_index()
    assert len(obs_t) == pre.num_transitions and obs_t.dtype == np.int64
    episode_of_row = np.repeat(np.arange(pre.num_episodes), a.episode_lengths + 1)
    np.testing.assert_array_equal(episode_of_row[obs_t], episode_of_row[obs_t1])
    # s' of transition k is what the env returned after action k: positions move accordingly
    from abco_envs.maze.layout import DELTAS, OPEN_BITS

    acts = pre.actions_of_transitions()
    layouts = a.layouts[episode_of_row[obs_t]]
    r, c = a.positions[obs_t].T
    opened = (layouts[np.arange(len(r)), r, c] & OPEN_BITS[acts]) > 0
    expect = a.positions[obs_t] + DELTAS[acts] * opened[:, None]
    np.testing.assert_array_equal(expect, a.positions[obs_t1])


def test_expert_actions_are_kept_apart(expert):
    with pytest.raises(WrongKindError, match="IDM accuracy"):
        expert.actions_of_transitions()
    acts = expert.actions_of_transitions(idm_eval=True)
    assert len(acts) == expert.num_transitions
    a = expert.load_arrays()
    assert a.actions is None and a.idm_eval_actions is not None
    with pytest.raises(WrongKindError):
        expert.sample_by_action([1, 1, 1, 1], 0)


def test_sample_by_action(pre):
    acts = pre.actions_of_transitions()
    have = np.bincount(acts, minlength=4)
    counts = [int(have[0]) + 5, 1, 0, 2]  # class 0 asks more than it has: replacement
    idx = pre.sample_by_action(counts, np.random.default_rng(0))
    np.testing.assert_array_equal(np.bincount(acts[idx], minlength=4), counts)
    small = idx[acts[idx] == 3]
    assert len(set(small.tolist())) == len(small)  # without replacement where possible
    again = pre.sample_by_action(counts, np.random.default_rng(0))
    np.testing.assert_array_equal(idx, again)
    assert len(pre.sample_by_action({1: 3}, 1)) == 3


def test_sample_by_action_is_uniform_within_class(pre):
    acts = pre.actions_of_transitions()
    rows = np.flatnonzero(acts == 1)
    idx = pre.sample_by_action({1: 20_000}, 3)
    freq = np.bincount(idx, minlength=len(acts))[rows] / 20_000
    assert np.allclose(freq, 1 / len(rows), atol=0.25 / len(rows) + 0.01)


def test_sample_missing_class(tmp_path):
    ds = abco_data.open_dataset(make_small("abco/maze3x3-pre-v0", tmp_path))
    acts = ds.actions_of_transitions()
    with pytest.raises(ValueError, match="no transition has action 7"):
        ds.sample_by_action({7: 1}, 0)
    assert len(ds.sample_by_action(np.bincount(acts), 0)) == len(acts)


def test_maze_reference(pre):
    ref = pre.reference
    assert len(ref.layout_ids) == 200 and ref.layout_splits.count("test") == 100
    from abco_envs.maze.layout import shortest_path_length
    from abco_envs.maze.pool import layout_pool

    pool = layout_pool(5)
    lengths = np.array([shortest_path_length(c) for c in pool.test])
    np.testing.assert_allclose(ref.expert_per_layout[100:], 1 - (lengths - 1) * 0.1 / 25)
    assert ref.layout_ids[:100] == pool.train_ids
    assert np.all(ref.random_per_layout < ref.expert_per_layout)
    assert ref.expert_mean == pytest.approx(ref.expert_per_layout[:100].mean())
    lid = ref.layout_ids[150]
    assert ref.performance(ref.expert_per_layout[150], lid) == pytest.approx(1.0)
    assert ref.performance(ref.random_per_layout[150], lid) == pytest.approx(0.0)


def test_load_arrays_memory_is_close_to_raw_bytes(tmp_path):
    path = make_small("abco/maze5x5-pre-v0", tmp_path, layouts=10, episodes_per_layout=20)
    ds = abco_data.open_dataset(path)
    tracemalloc.start()
    a = ds.load_arrays()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert a.nbytes > 10e6
    assert peak <= 1.2 * a.nbytes


def test_pickles_without_its_handle(pre):
    pre.episode(0)
    clone = pickle.loads(pickle.dumps(pre))
    np.testing.assert_array_equal(clone.episode(1).observations, pre.episode(1).observations)
    clone.close()


def test_read_transitions(pre):
    a = pre.load_arrays()
    obs_t, obs_t1 = pre.transition_index()
    idx = np.array([5, 0, 5, pre.num_transitions - 1])
    s, act, s1 = pre.read_transitions(idx)
    np.testing.assert_array_equal(s, a.observations[obs_t[idx]])
    np.testing.assert_array_equal(s1, a.observations[obs_t1[idx]])
    np.testing.assert_array_equal(act, a.actions[idx])
    with pytest.raises(IndexError):
        pre.read_transitions([pre.num_transitions])
