"""Tests for the training-free expert controllers of the classic-control envs and
LunarLander (Gymnasium's heuristic; more in test_lunar_lander.py)."""

from __future__ import annotations

import numpy as np
import pytest

from abco_envs import CLASSIC_IDS
from abco_envs.experts.classic import CONTROLLERS, controller_for, rollout_returns

EPISODES = 100


@pytest.mark.parametrize("env_id", CLASSIC_IDS)
def test_expert_meets_threshold(env_id: str) -> None:
    returns = rollout_returns(env_id, episodes=EPISODES, seed=0)
    assert returns.shape == (EPISODES,)
    assert returns.dtype == np.float64
    if env_id == "CartPole-v1":
        assert np.all(returns == 500.0), returns
    elif env_id == "MountainCar-v0":
        assert returns.mean() >= -110.0, returns.mean()
    elif env_id == "LunarLander-v3":
        assert returns.mean() >= 200.0, returns.mean()  # the env's "solved" line
    else:
        assert returns.mean() >= -80.0, returns.mean()


def test_every_classic_id_has_a_controller() -> None:
    assert set(CONTROLLERS) == set(CLASSIC_IDS)


@pytest.mark.parametrize("env_id", CLASSIC_IDS)
def test_expert_is_deterministic(env_id: str) -> None:
    first = rollout_returns(env_id, episodes=5, seed=123)
    second = rollout_returns(env_id, episodes=5, seed=123)
    np.testing.assert_array_equal(first, second)


@pytest.mark.parametrize("env_id", sorted(CONTROLLERS))
def test_controller_for_known_ids(env_id: str) -> None:
    assert controller_for(env_id) is CONTROLLERS[env_id]


def test_controller_for_unknown_id() -> None:
    with pytest.raises(ValueError, match="Nope-v0"):
        controller_for("Nope-v0")
