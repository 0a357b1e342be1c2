"""The success rule table (abco_envs.success): one rule per environment, each decided as the
module documents it."""

from __future__ import annotations

import numpy as np
import pytest

import abco_envs
from abco_envs.success import SUCCESS_RULES, SuccessRule, is_success, success_mask


def test_every_env_has_a_rule() -> None:
    assert set(SUCCESS_RULES) == {*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS}


@pytest.mark.parametrize("maze_id", abco_envs.MAZE_IDS)
def test_maze_success_is_the_goal_reached(maze_id: str) -> None:
    assert is_success(maze_id, terminated=True, length=7, episode_return=0.98)
    assert is_success(f"abco_envs:{maze_id}", terminated=True, length=7, episode_return=0.98)
    assert not is_success(maze_id, terminated=False, length=1000, episode_return=-0.5)


def test_cartpole_success_is_195_steps_survived() -> None:
    assert SUCCESS_RULES["CartPole-v1"] == SuccessRule("steps", 195)
    assert is_success("CartPole-v1", terminated=True, length=195, episode_return=195.0)
    assert is_success("CartPole-v1", terminated=False, length=500, episode_return=500.0)
    assert not is_success("CartPole-v1", terminated=True, length=194, episode_return=194.0)
    # Known on the 195th step, before the episode ends.
    running = success_mask("CartPole-v1", terminated=[False, False], lengths=[195, 100],
                           returns=[195.0, 100.0], ended=[False, False])
    assert running.tolist() == [True, False]


@pytest.mark.parametrize("env_id", ["MountainCar-v0", "Acrobot-v1"])
def test_termination_is_success(env_id: str) -> None:
    assert is_success(env_id, terminated=True, length=90, episode_return=-89.0)
    assert not is_success(env_id, terminated=False, length=200, episode_return=-200.0)


def test_lunar_lander_success_is_a_return_of_200_at_the_end() -> None:
    rule = SUCCESS_RULES["LunarLander-v3"]
    assert (rule.kind, rule.threshold) == ("return", 200.0)
    assert is_success("LunarLander-v3", terminated=True, length=250, episode_return=200.0)
    assert is_success("LunarLander-v3", terminated=False, length=1000, episode_return=230.0)
    # A crash terminates too: termination is no verdict.
    assert not is_success("LunarLander-v3", terminated=True, length=90, episode_return=-120.0)
    assert not is_success("LunarLander-v3", terminated=True, length=300, episode_return=199.9)
    # A running episode's return is not final: no success before its end.
    mask = success_mask("LunarLander-v3", terminated=[False, True, False],
                        lengths=[300, 300, 1000], returns=[250.0, 250.0, 250.0],
                        ended=[False, True, True])
    assert mask.tolist() == [False, True, True]


def test_is_success_in_info_decides() -> None:
    # An env without a rule, judged by what it reports.
    assert is_success("FetchReach-v4", terminated=False, length=50, episode_return=-3.0,
                      info={"is_success": 1.0})
    assert not is_success("FetchReach-v4", terminated=True, length=50, episode_return=0.0,
                          info={"is_success": False})
    # Reported beside a rule, the report wins.
    assert not is_success("Acrobot-v1", terminated=True, length=80, episode_return=-79.0,
                          info={"is_success": False})
    # A vector env's info: only the slots its mask marks reported; the others keep the rule.
    info = {"is_success": np.array([True, False, False]),
            "_is_success": np.array([True, True, False])}
    mask = success_mask("Acrobot-v1", terminated=[False, True, True], lengths=[10, 10, 10],
                        returns=[-9.0] * 3, ended=[True] * 3, info=info)
    assert mask.tolist() == [True, False, True]


def test_an_env_without_rule_or_report_is_refused() -> None:
    with pytest.raises(abco_envs.UnknownEnvError, match="Pendulum-v1"):
        is_success("Pendulum-v1", terminated=False, length=200, episode_return=-150.0)


def test_unknown_rule_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="'reward'"):
        SuccessRule("reward", 1.0)
