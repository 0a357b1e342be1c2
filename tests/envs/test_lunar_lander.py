"""LunarLander-v3: Gymnasium's heuristic as abco's expert, and the one line a missing Box2D
gives (the import failure is simulated: Box2D is installed with the dev extra)."""

from __future__ import annotations

import sys

import gymnasium as gym
import pytest
from gymnasium.envs.box2d.lunar_lander import heuristic
from gymnasium.error import DependencyNotInstalled

import abco_data
import abco_envs
from abco_envs.experts import expert_policy
from abco_envs.experts.classic import rollout_returns
from abco_envs.experts.lunar_lander import lunar_lander_action

INSTALL = 'pip install "abco[box2d]"'


def test_expert_lands_above_the_solved_line() -> None:
    returns = rollout_returns("LunarLander-v3", episodes=20, seed=0)
    assert returns.mean() > 200.0, returns


def test_expert_is_gymnasiums_heuristic_on_the_env() -> None:
    """The stand-in env the expert hands the heuristic gives the actions the real env does."""
    env = gym.make("LunarLander-v3")
    policy = expert_policy("LunarLander-v3", seed=0)
    obs, info = env.reset(seed=3)
    for _ in range(300):
        action = policy(obs, info)
        assert action == heuristic(env, obs) and isinstance(action, int)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert env.action_space.contains(lunar_lander_action(obs))


@pytest.fixture
def no_box2d(monkeypatch: pytest.MonkeyPatch) -> None:
    """Box2D's import fails, as where the extra is not installed."""
    monkeypatch.setitem(sys.modules, "Box2D", None)


def _one_line_naming_the_extra(message: str) -> None:
    assert "\n" not in message.strip()
    assert "LunarLander-v3" in message and INSTALL in message


def test_missing_box2d_is_one_line_naming_the_extra(no_box2d) -> None:
    for use in (lambda: abco_envs.check_env_dependencies("LunarLander-v3"),
                lambda: expert_policy("LunarLander-v3")):
        with pytest.raises(abco_envs.MissingDependencyError) as err:
            use()
        assert isinstance(err.value, DependencyNotInstalled)  # as Gymnasium's own
        _one_line_naming_the_extra(str(err.value))
    abco_envs.check_env_dependencies("CartPole-v1")  # other envs need nothing more


def test_missing_box2d_generates_nothing(no_box2d, tmp_path) -> None:
    target = tmp_path / "ll.hdf5"
    with pytest.raises(abco_envs.MissingDependencyError):
        abco_data.generate("abco/lunarlander-pre-v0", target, progress=False, transitions=10)
    assert not target.exists()


def test_missing_box2d_on_the_command_line(no_box2d, tmp_path, capsys) -> None:
    from abco_data.cli import main as data_main
    from abco_train.cli import main

    commands = [
        lambda: main(["train", "--env", "LunarLander-v3", "--method", "bc", "--quiet",
                      "--run-dir", str(tmp_path / "run")]),
        lambda: main(["data", "generate", "abco/lunarlander-expert-v0",
                      "--out", str(tmp_path / "e.hdf5")]),
        lambda: data_main(["generate", "abco/lunarlander-pre-v0", "--out",
                           str(tmp_path / "p.hdf5")]),
    ]
    for command in commands:
        assert command() == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and "Traceback" not in err
        _one_line_naming_the_extra(err)
    assert not any(tmp_path.iterdir())  # refused before any work
