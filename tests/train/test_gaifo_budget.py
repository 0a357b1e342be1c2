"""GAIfO's published PPO settings (the RL Baselines3 Zoo's table, its schedules and
VecNormalize) and the run's --budget: whole rollouts, never past it, a clear failure below one."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from train_testing import gaifo_config

from abco_train.config.run import ConfigError, RunConfig, known_envs
from abco_train.harness.loop import train
from abco_train.harness.runtime import seed_everything
from abco_train.harness.training_data import load_training_data
from abco_train.methods.registry import get_method, resolve_config

pytest.importorskip("stable_baselines3")

from abco_train.methods.gaifo.method import GAIfO  # noqa: E402
from abco_train.methods.gaifo.options import (  # noqa: E402
    COMMON_OPTIONS,
    ZOO_PPO,
    GAIfOOptions,
    ppo_family,
)


def make_method(env_id, data, run_dir, **changes) -> GAIfO:
    cfg = resolve_config(gaifo_config(env_id, data, run_dir, **changes))
    method = get_method("gaifo")(cfg, load_training_data(cfg), seed_everything(cfg.seed))
    assert isinstance(method, GAIfO)
    return method


def rows_of(run_dir):
    return [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]


# -- the Zoo's table ------------------------------------------------------------------------------


def test_the_zoo_table_covers_every_builtin_env_family():
    families = {ppo_family(env) for env in known_envs()}
    assert families <= set(ZOO_PPO), families - set(ZOO_PPO)
    assert {"maze", "CartPole-v1", "Acrobot-v1", "MountainCar-v0", "LunarLander-v3"} <= set(ZOO_PPO)
    for family, row in ZOO_PPO.items():
        assert set(row) <= set(COMMON_OPTIONS), family  # options of GAIfO's, nothing else
        GAIfOOptions.resolve({}, {**COMMON_OPTIONS, **row}, "gaifo").check()  # values that fit


def test_the_zoo_rows_are_the_published_ones():
    """Rollouts (n_envs x n_steps), minibatch, epochs, discount, GAE, entropy, normalize and
    schedules of hyperparams/ppo.yml; what a row leaves out is SB3's PPO default."""

    def row(family):
        o = GAIfOOptions.resolve({}, {**COMMON_OPTIONS, **ZOO_PPO[family]}, "gaifo")
        return (o.n_envs, o.n_steps, o.batch_size, o.n_epochs, o.gamma, o.gae_lambda,
                o.ent_coef, o.learning_rate, o.learning_rate_schedule, o.clip_range,
                o.clip_range_schedule, o.normalize)  # fmt: skip

    assert row("CartPole-v1") == (8, 32, 256, 20, 0.98, 0.8, 0.0, 1e-3, "linear", 0.2,
                                  "linear", False)  # fmt: skip
    assert row("Acrobot-v1") == (16, 256, 64, 4, 0.99, 0.94, 0.0, 3e-4, "constant", 0.2,
                                 "constant", True)  # fmt: skip
    assert row("MountainCar-v0") == (16, 16, 64, 4, 0.99, 0.98, 0.0, 3e-4, "constant", 0.2,
                                     "constant", True)  # fmt: skip
    assert row("LunarLander-v3") == (16, 1024, 64, 4, 0.999, 0.98, 0.01, 3e-4, "constant",
                                     0.2, "constant", False)  # fmt: skip
    assert row("maze") == (8, 128, 64, 10, 0.99, 0.95, 0.0, 2.5e-4, "constant", 0.2,
                           "constant", True)  # fmt: skip
    for family in ZOO_PPO:  # SB3's defaults where no row names a value
        o = GAIfOOptions.resolve({}, {**COMMON_OPTIONS, **ZOO_PPO[family]}, "gaifo")
        assert (o.vf_coef, o.max_grad_norm, o.net_arch) == (0.5, 0.5, [64, 64])


def test_a_run_gets_its_familys_row_and_the_flags_still_win():
    maze = GAIfOOptions.for_run(RunConfig(env="AbcoMaze10x10-v0", method="gaifo"))
    assert (maze.n_envs, maze.n_steps, maze.learning_rate) == (8, 128, 2.5e-4)
    given = {"n_envs": 4, "learning_rate_schedule": "constant", "normalize": False}
    acrobot = GAIfOOptions.for_run(RunConfig(env="Acrobot-v1", method="gaifo",
                                             method_options=given))  # fmt: skip
    assert (acrobot.n_envs, acrobot.n_steps, acrobot.normalize) == (4, 256, False)


def test_rl_steps_below_one_rollout_is_a_config_error():
    with pytest.raises(ConfigError, match=r"--gaifo-rl-steps must be at least one PPO rollout "
                                          r"\(--gaifo-n-steps x --gaifo-n-envs = 256\), got 100"):
        GAIfOOptions.for_run(RunConfig(env="CartPole-v1", method="gaifo",
                                       method_options={"rl_steps": 100}))  # fmt: skip
    with pytest.raises(ConfigError, match="--gaifo-learning-rate-schedule must be one of"):
        GAIfOOptions.for_run(RunConfig(env="CartPole-v1", method="gaifo",
                                       method_options={"learning_rate_schedule": "cosine"}))


# -- the budget -----------------------------------------------------------------------------------


def test_the_budget_caps_rl_steps_in_whole_rollouts(tiny_data, tmp_path):
    # 70 pays for 2 rounds of 32 (of the 3 that rl_steps 96 plans) over 3 iterations: 1, 1, 0
    final = train(gaifo_config("AbcoMaze3x3-v0", tiny_data, tmp_path, iterations=2, budget=70))
    assert final is not None
    assert final["status"] == "ok"
    assert final["interactions"]["rl"] == 64 and final["interactions"]["rl"] % 32 == 0
    rows = rows_of(tmp_path)
    assert [r["interactions"]["rl"] for r in rows] == [32, 64, 64]
    assert [r["train"]["rounds"] for r in rows] == [1, 1, 0]
    assert rows[0]["train"]["rl_steps_planned"] == 64


def test_a_budget_above_rl_steps_changes_nothing(tiny_data, tmp_path):
    train(gaifo_config("AbcoMaze3x3-v0", tiny_data, tmp_path, budget=10_000))
    assert [r["interactions"]["rl"] for r in rows_of(tmp_path)] == [64, 96]


def test_a_budget_below_one_rollout_fails_clearly(tiny_data, tmp_path):
    final = train(gaifo_config("AbcoMaze3x3-v0", tiny_data, tmp_path, budget=31))
    assert final is not None
    assert final["status"] == "budget_too_small"
    assert final["message"] == (
        "the run's --budget of 31 interactions cannot pay for one PPO rollout of 32 env steps "
        "(--gaifo-n-steps 16 x --gaifo-n-envs 2); give a budget of at least 32 or smaller "
        "rollouts")  # fmt: skip
    assert final["interactions"]["rl"] == 0
    assert "performance" not in json.dumps(final)  # no result to average by mistake


def test_the_last_iteration_takes_only_what_is_left(tiny_data, tmp_path):
    method = make_method("AbcoMaze3x3-v0", tiny_data, tmp_path, iterations=1, budget=80)
    assert method.rounds_total == 2  # 80 // 32
    method.interactions["pre_demonstration"] = 20  # spent by something else: 60 left
    assert method.rounds_of(0) == 1
    method.train_iteration(0)
    assert method.budget_left == 28 and method.rounds_of(1) == 0  # not one more round
    method.train_iteration(1)
    assert method.interactions["rl"] == 32


# -- schedules and VecNormalize -------------------------------------------------------------------


def test_linear_schedules_run_over_the_runs_planned_steps(tiny_data, tmp_path):
    method = make_method("CartPole-v1", tiny_data, tmp_path)  # lin_0.001, lin_0.2; 3 rounds
    lr = lambda: method.model.policy.optimizer.param_groups[0]["lr"]  # noqa: E731
    assert lr() == pytest.approx(1e-3)
    method.train_iteration(0)  # rounds 1-2 of 3: the last update at progress 1/3
    assert lr() == pytest.approx(1e-3 / 3)
    clip_range: Any = method.model.clip_range  # SB3 makes it a schedule
    assert clip_range(1.0) == pytest.approx(0.2 / 3)
    method.train_iteration(1)  # the run's last update at progress 0, as in the Zoo
    assert lr() == pytest.approx(0.0, abs=1e-12)
    constant = make_method("AbcoMaze3x3-v0", tiny_data, tmp_path / "maze")
    constant.train_iteration(0)
    assert constant.model.policy.optimizer.param_groups[0]["lr"] == pytest.approx(2.5e-4)


@pytest.mark.parametrize(("env_id", "obs"), [("Acrobot-v1", True), ("AbcoMaze3x3-v0", False),
                                             ("CartPole-v1", None)])  # fmt: skip
def test_vecnormalize_where_the_zoo_normalizes(env_id, obs, tiny_data, tmp_path):
    method = make_method(env_id, tiny_data, tmp_path)
    norm = method.normalizer
    assert (None if norm is None else norm.norm_obs) == obs
    if norm is None:
        return
    assert norm.norm_reward and norm.gamma == method.options.gamma
    assert method.model.get_vec_normalize_env() is norm and norm.venv is method.env  # D: raw
    method.train_iteration(0)
    batch = method.data.expert_obs[:5]
    expected, _ = method.model.predict(norm.normalize_obs(batch), deterministic=True)
    np.testing.assert_array_equal(method.act(batch), expected)
    state = method.state_dict()["normalizer"]
    other = make_method(env_id, tiny_data, tmp_path / "other")
    other.load_state_dict(method.state_dict())
    for key, value in state.items():
        np.testing.assert_array_equal(other.state_dict()["normalizer"][key], value)
    with pytest.raises(ValueError, match="shape"):
        other.load_state_dict({**method.state_dict(),
                               "normalizer": {**state, "return_mean": np.zeros(3)}})
    with pytest.raises(ValueError, match="finite"):
        other.load_state_dict({**method.state_dict(),
                               "normalizer": {**state, "return_count": float("nan")}})
