"""Bad input to the mazes ends in abco's own errors, naming what was wrong and the bad value."""

import re

import gymnasium as gym
import numpy as np
import pytest

import abco_envs
from abco_envs import (
    MAZE_IDS,
    Action,
    InvalidActionError,
    InvalidOptionError,
    OptionOutOfRangeError,
    UnknownEnvError,
    maze_size,
)
from abco_envs.experts import controller_for, expert_policy


def _make_vec(env_id, num_envs=3, **kwargs):
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


@pytest.fixture(params=MAZE_IDS)
def env_id(request):
    return request.param


@pytest.mark.parametrize("action", [0, 3, np.int64(1), np.uint8(2), np.int32(3), Action.W,
                                    np.array(1)])
def test_integer_actions_of_any_kind_step(env_id, action):
    env = gym.make(env_id)
    env.reset(seed=0)
    env.step(action)
    envs = _make_vec(env_id, num_envs=2)
    envs.reset(seed=0)
    envs.step(np.array([action, action]))


@pytest.mark.parametrize(
    "action", [1.5, np.float64(1.0), "1", None, True, np.bool_(False), [1], 4, -1, np.int64(9)]
)
def test_bad_actions_are_refused_and_change_nothing(env_id, action):
    env = gym.make(env_id)
    _, info = env.reset(seed=0)
    with pytest.raises(InvalidActionError, match=re.escape(f"invalid action {action!r}")):
        env.step(action)
    assert isinstance(InvalidActionError(), ValueError)
    *_, after = env.step(Action.N)  # the failed step moved nothing: (0, 0) is closed to N
    assert after["position"].tolist() == info["position"].tolist()


@pytest.mark.parametrize(
    ("actions", "match"),
    [
        ([0.5, 1, 2], "dtype float64"),
        (["1", "2", "3"], "dtype <U1"),
        ([True, False, True], "dtype bool"),
        (None, "dtype object"),
        ([0, 1], "expected 3 actions"),
        ([0, 1, 9], "invalid action 9 for maze 2"),
        ([-1, 1, 2], "invalid action -1 for maze 0"),
    ],
)
def test_bad_vector_actions_are_refused(env_id, actions, match):
    envs = _make_vec(env_id)
    envs.reset(seed=0)
    with pytest.raises(InvalidActionError, match=re.escape(match)):
        envs.step(actions)


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        ("layout", InvalidOptionError, "reset options must be a dict"),
        ({"layuot_index": 1}, InvalidOptionError, "unknown reset option(s) 'layuot_index'"),
        ({"layout_index": 2.7}, InvalidOptionError, "'layout_index' must be an integer, got 2.7"),
        ({"layout_index": "3"}, InvalidOptionError, "'layout_index' must be an integer, got '3'"),
        ({"layout_index": True}, InvalidOptionError, "'layout_index' must be an integer"),
        ({"layout_index": 100}, OptionOutOfRangeError, "'layout_index' 100 is out of range"),
        ({"layout_index": -1}, OptionOutOfRangeError, "'layout_index' -1 is out of range"),
        ({"start": (1.5, 2.7)}, InvalidOptionError, "'start' must be a (row, col) pair"),
        ({"start": "ab"}, InvalidOptionError, "'start' must be a (row, col) pair"),
        ({"start": (1,)}, InvalidOptionError, "'start' must be a (row, col) pair"),
        ({"start": (1, 1, 1)}, InvalidOptionError, "'start' must be a (row, col) pair"),
        ({"start": (True, 0)}, InvalidOptionError, "'start' must be a (row, col) pair"),
        ({"start": (0, -1)}, OptionOutOfRangeError, "'start' (0, -1) is outside"),
    ],
)
def test_bad_reset_options_are_refused(env_id, options, error, match):
    env = gym.make(env_id)
    with pytest.raises(error, match=re.escape(match)):
        env.reset(seed=0, options=options)
    envs = _make_vec(env_id)
    with pytest.raises(error, match=re.escape(match)):
        envs.reset(seed=0, options=options)


def test_out_of_range_options_are_still_index_and_value_errors():
    env = gym.make("AbcoMaze3x3-v0")
    with pytest.raises(IndexError):
        env.reset(options={"layout_index": 100})
    with pytest.raises(ValueError):
        env.reset(options={"start": (3, 0)})


def test_a_start_on_the_goal_is_refused(env_id):
    n = maze_size(env_id)
    goal = (n - 1, n - 1)
    with pytest.raises(InvalidOptionError, match=re.escape(f"'start' {goal!r} is the goal")):
        gym.make(env_id).reset(seed=0, options={"start": goal})
    envs = _make_vec(env_id, num_envs=2)
    with pytest.raises(InvalidOptionError, match="is the goal"):
        envs.reset(seed=0, options={"start": [(0, 0), goal]})
    # A start one cell before the goal is fine, given as numpy integers or a numpy row.
    _, info = gym.make(env_id).reset(seed=0, options={"start": (np.int64(n - 2), n - 1)})
    assert info["position"].tolist() == [n - 2, n - 1]
    _, info = envs.reset(seed=0, options={"start": np.array([[0, 0], [n - 1, n - 2]])})
    assert info["position"].tolist() == [[0, 0], [n - 1, n - 2]]


def test_a_failed_vector_reset_leaves_every_maze_as_it_was():
    envs = _make_vec("AbcoMaze5x5-v0")
    _, before = envs.reset(seed=0, options={"start": [(1, 1), (2, 2), (3, 3)]})
    for options in ({"start": [(0, 0), (0, 0), (4, 4)]}, {"layout_index": [0, 1, 100]}):
        with pytest.raises(InvalidOptionError):
            envs.reset(options=options)
        assert np.array_equal(envs.unwrapped.positions, before["position"])
        assert envs.unwrapped.layout_indices.tolist() == before["layout_index"].tolist()


def test_layout_index_is_refused_by_a_fresh_env():
    env = gym.make("AbcoMaze5x5-v0", split="fresh")
    with pytest.raises(InvalidOptionError, match="'layout_index' 3 needs an indexed split"):
        env.reset(seed=0, options={"layout_index": 3})


@pytest.mark.parametrize(
    ("image_size", "match"),
    [
        ("64", "image_size must be an integer or a (height, width) pair"),
        ((3,), "got (3,) (tuple)"),
        ((64, 64, 3), "got (64, 64, 3) (tuple)"),
        (64.0, "got 64.0 (float)"),
        ((64.0, 64), "got (64.0, 64) (tuple)"),
        (True, "got True (bool)"),
        (None, "got None (NoneType)"),
        (5, "image_size 5 is too small"),
        ((64, 0), "image_size (64, 0) is too small"),
        (-64, "image_size -64 is too small"),
    ],
)
def test_bad_image_sizes_are_refused(env_id, image_size, match):
    with pytest.raises(InvalidOptionError, match=re.escape(match)):
        gym.make(env_id, image_size=image_size)
    with pytest.raises(InvalidOptionError, match=re.escape(match)):
        _make_vec(env_id, image_size=image_size)


def test_image_size_pairs_of_numpy_integers_work(env_id):
    env = gym.make(env_id, image_size=np.array([40, 60]))
    assert env.reset(seed=0)[0].shape == (40, 60, 3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"obs_type": "pixels"}, "unknown obs_type 'pixels'"),
        ({"split": "valid"}, "unknown split 'valid'"),
        ({"render_mode": "ansi"}, "unknown render_mode 'ansi'"),
        ({"size": 2.5}, "size=2.5 (float)"),
        ({"size": 1}, "size=1 (int)"),
        ({"size": 10**6}, "size from 2 to 64 cells, got size=1000000"),
        ({"image_size": (50_000, 50_000)}, "at most 4096 pixels a side"),
        ({"image_size": 4097}, "image_size 4097 is too large"),
    ],
)
def test_bad_constructor_arguments_are_refused(kwargs, match):
    with pytest.raises(InvalidOptionError, match=re.escape(match)):
        abco_envs.MazeEnv(**kwargs)
    with pytest.raises(InvalidOptionError, match=re.escape(match)):
        abco_envs.MazeVectorEnv(num_envs=2, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"num_envs": 0}, "num_envs must be an integer from 1 to 65536, got 0"),
     ({"num_envs": 2.0}, "got 2.0"),
     ({"num_envs": 10**6}, "from 1 to 65536, got 1000000"),
     ({"num_envs": 1000, "image_size": 4096}, "would take about 187.5 GiB (at most 16 GiB): use"
                                              " at most 85 of them"),
     ({"max_episode_steps": 0}, "max_episode_steps must be None or an integer of at least 1")],
)
def test_bad_vector_arguments_are_refused(kwargs, match):
    with pytest.raises(InvalidOptionError, match=re.escape(match)):
        abco_envs.MazeVectorEnv(**{"num_envs": 2, **kwargs})


def test_bounds_are_refused_before_anything_is_allocated(monkeypatch):
    """Through gym's own constructors too; nothing of the refused size is ever built."""
    import gymnasium as gym

    from abco_envs.maze import vector

    def no_batch(*args, **kwargs):
        raise AssertionError("the refused env allocated its observation batch")

    monkeypatch.setattr(vector, "batch_space", no_batch)
    with pytest.raises(InvalidOptionError, match="num_envs must be an integer from 1 to 65536"):
        gym.make_vec("AbcoMaze5x5-v0", num_envs=10**6)
    with pytest.raises(InvalidOptionError, match="at most 4096 pixels a side"):
        gym.make("AbcoMaze5x5-v0", image_size=(50_000, 50_000))
    with pytest.raises(InvalidOptionError, match="at most 4096 pixels a side"):
        gym.make_vec("AbcoMaze5x5-v0", num_envs=2, image_size=(50_000, 50_000))


@pytest.mark.parametrize("helper", [maze_size, expert_policy, controller_for])
@pytest.mark.parametrize("env_id", ["AbcoMaze4x4-v0", "Foo-v0", 5, None])
def test_unknown_env_ids_given_to_abco_helpers(helper, env_id):
    with pytest.raises(UnknownEnvError, match=re.escape(repr(env_id))) as caught:
        helper(env_id)
    assert isinstance(caught.value, ValueError)


def test_known_ids_still_work_in_the_helpers():
    assert [maze_size(f"abco_envs:{i}") for i in MAZE_IDS] == [3, 5, 10]
    assert controller_for("CartPole-v1") is controller_for("gymnasium:CartPole-v1")
    assert callable(expert_policy(MAZE_IDS[0], seed=0))
