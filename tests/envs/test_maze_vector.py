"""The native vector env equals SyncVectorEnv step for step."""

import gymnasium as gym
import numpy as np
import pytest

from abco_envs import MAZE_IDS, MazeVectorEnv


def _assert_steps_equal(a, b):
    for x, y in zip(a[:4], b[:4]):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert a[4].keys() == b[4].keys()
    for key in a[4]:
        assert np.array_equal(a[4][key], b[4][key]), key


@pytest.mark.parametrize("env_id", MAZE_IDS)
@pytest.mark.parametrize("obs_type", ["image", "state"])
def test_equal_to_sync_vector_env(env_id, obs_type):
    kwargs = {"num_envs": 6, "max_episode_steps": 25, "obs_type": obs_type}
    sync = gym.make_vec(env_id, vectorization_mode="sync", **kwargs)
    native = gym.make_vec(env_id, vectorization_mode="vector_entry_point", **kwargs)
    assert isinstance(native.unwrapped, MazeVectorEnv)
    assert native.observation_space == sync.observation_space
    assert native.action_space == sync.action_space
    oa, ia = sync.reset(seed=9)
    ob, ib = native.reset(seed=9)
    assert np.array_equal(oa, ob) and ia.keys() == ib.keys()
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(120):
        actions = rng.integers(4, size=6)
        a, b = sync.step(actions), native.step(actions)
        _assert_steps_equal(a, b)
        ended += int(np.sum(a[2] | a[3]))
    assert ended > 6  # autoresets (both termination and truncation) were exercised


def test_per_env_reset_options_and_errors():
    envs = gym.make_vec("AbcoMaze5x5-v0", num_envs=3, vectorization_mode="vector_entry_point")
    obs, info = envs.reset(seed=0, options={"layout_index": [4, 5, 6], "start": [(0, 0), (1, 1),
                                                                               (2, 2)]})
    assert info["layout_index"].tolist() == [4, 5, 6]
    assert info["position"].tolist() == [[0, 0], [1, 1], [2, 2]]
    with pytest.raises(ValueError, match="once per maze"):
        envs.reset(options={"layout_index": [1, 2]})
    with pytest.raises(ValueError, match="expected 3 actions"):
        envs.step([0, 1])
    with pytest.raises(ValueError, match="invalid action"):
        envs.step([0, 1, 9])


def test_reset_takes_one_seed_per_maze():
    envs = gym.make_vec("AbcoMaze3x3-v0", num_envs=2, vectorization_mode="vector_entry_point")
    obs, info = envs.reset(seed=[7, None])
    again, info_again = envs.reset(seed=[7, 8])
    assert np.array_equal(obs[0], again[0]) and info["layout_id"][0] == info_again["layout_id"][0]
    with pytest.raises(ValueError, match="expected 2 seeds"):
        envs.reset(seed=[1, 2, 3])


def test_vector_observations_are_fresh():
    envs = gym.make_vec("AbcoMaze3x3-v0", num_envs=2, vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=0)
    kept = obs.copy()
    envs.step([1, 2])
    assert np.array_equal(obs, kept)
