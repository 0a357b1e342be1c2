"""GAIfO (abco_train.methods.gaifo): runs on every env, its discriminator, its counts, its
seeding, its options, its stable-baselines3 pieces."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import numpy as np
import pytest
import torch
from train_testing import GAIFO_TINY as TINY
from train_testing import gaifo_config

import abco_envs
from abco_train.config.fields import add_field_options
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.loop import train
from abco_train.harness.runtime import seed_everything
from abco_train.harness.trained_policy import load_policy
from abco_train.harness.training_data import load_training_data
from abco_train.methods.base import INTERACTION_KINDS
from abco_train.methods.registry import get_method, resolve_config

pytest.importorskip("stable_baselines3")

from abco_train.methods.gaifo.method import (  # noqa: E402
    EXPERT_LABEL,
    LEARNER_LABEL,
    REWARDS,
    GAIfO,
    reward_from_logits,
)
from abco_train.methods.gaifo.options import (  # noqa: E402
    COMMON_OPTIONS,
    GAIFO_DEFAULTS,
    ZOO_PPO,
    GAIfOOptions,
)

ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)

def make_method(env_id, data, run_dir, **options) -> GAIfO:
    cfg = resolve_config(gaifo_config(env_id, data, run_dir, method_options=options))
    return get_method("gaifo")(cfg, load_training_data(cfg), seed_everything(cfg.seed))


@pytest.mark.parametrize("env_id", ENVS)
def test_gaifo_runs_on_every_env_and_counts_its_rl_steps(env_id, tiny_data, tmp_path):
    final = train(gaifo_config(env_id, tiny_data, tmp_path))
    key = "train/paper" if env_id in abco_envs.MAZE_IDS else "episodes"
    assert final["status"] == "ok" and np.isfinite(final[key]["performance"])
    stored = json.loads((tmp_path / "final.json").read_text())["interactions"]
    assert set(stored) == set(INTERACTION_KINDS)
    # 96 steps = 3 rounds of 32 over 2 iterations (2 + 1); nothing else is spent
    assert stored == {"pre_demonstration": 0, "post_demonstration": 0, "rl": 96, "remapping": 0}
    rows = [json.loads(x) for x in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert [r["interactions"]["rl"] for r in rows] == [64, 96]
    assert [r["train"]["rl_steps"] for r in rows] == [64, 32]
    assert rows[0]["train"]["options"]["rl_steps"] == 96


@pytest.mark.parametrize("preset", ["general", "cpu"])
def test_gaifo_on_a_maze_reads_frames_with_the_presets_networks(preset, tiny_data, tmp_path):
    """The general preset's cell networks (``cellplan``) need the maze's grid: the
    discriminator gets it, and the cpu preset's compact CNN is what it was."""
    final = train(gaifo_config("AbcoMaze5x5-v0", tiny_data, tmp_path, preset=preset))
    assert final["status"] == "ok" and np.isfinite(final["train/paper"]["performance"])
    cfg = resolve_config(gaifo_config("AbcoMaze5x5-v0", tiny_data, tmp_path, preset=preset))
    assert cfg.arch == {"general": "cellplan", "cpu": "cnn"}[preset]


@pytest.mark.parametrize("env_id", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_discriminator_labels_expert_pairs_1_and_learner_pairs_0(env_id, tiny_data, tmp_path):
    assert (EXPERT_LABEL, LEARNER_LABEL) == (1.0, 0.0)
    method = make_method(env_id, tiny_data, tmp_path, d_lr=3e-3, d_batch_size=64)
    data = method.data
    rows = data.expert_t[:64]
    expert_s, expert_s1 = data.expert_obs[rows], data.expert_obs[rows + 1]
    if env_id in abco_envs.MAZE_IDS:  # the learner stands still (into a wall); the expert moves
        learner_s, learner_s1 = expert_s, expert_s.copy()
    else:  # the learner's states are far from the expert's
        learner_s, learner_s1 = expert_s + 3.0, expert_s1 + 3.0

    def logits():
        return (method.logits(expert_s, expert_s1).mean().item(),
                method.logits(learner_s, learner_s1).mean().item())  # fmt: skip

    before = logits()
    # one update (one minibatch: 64 learner pairs against 64 expert pairs)
    method.expert_t = torch.from_numpy(rows)  # the expert pairs above, no others
    method.update_discriminator(learner_s, learner_s1)
    after = logits()
    # the expert pairs' logits rise relative to the learner's (one Adam step may shift both)
    assert after[0] - after[1] > before[0] - before[1]
    for _ in range(30):
        stats = method.update_discriminator(learner_s, learner_s1)
    expert_logit, learner_logit = logits()
    assert expert_logit > 0 > learner_logit  # D = P(expert) > 0.5 on expert pairs only
    assert stats["d_expert_accuracy"] == 1.0 and stats["d_learner_accuracy"] == 1.0
    for form in REWARDS:  # every reward form prefers the expert-like pairs
        method.options.reward = form
        assert (method.reward(expert_s, expert_s1).mean()
                > method.reward(learner_s, learner_s1).mean())  # fmt: skip


def test_reward_forms():
    logits = torch.linspace(-4, 4, 9)
    d = torch.sigmoid(logits)
    torch.testing.assert_close(reward_from_logits(logits, "logit"), torch.log(d) - torch.log(1 - d))
    torch.testing.assert_close(reward_from_logits(logits, "gail"), -torch.log(1 - d))
    torch.testing.assert_close(reward_from_logits(logits, "log_d"), torch.log(d))
    assert reward_from_logits(torch.tensor([50.0]), "logit", clip=10.0).item() == 10.0
    with pytest.raises(ValueError, match="unknown reward"):
        reward_from_logits(logits, "wasserstein")


def test_learner_rewards_come_from_the_discriminator_not_the_env(tiny_data, tmp_path):
    method = make_method("CartPole-v1", tiny_data, tmp_path)
    method.model.learn(32, reset_num_timesteps=False)
    s, s1, rewards = method.env.take_pairs()
    assert len(s) == len(s1) == len(rewards) == 32
    np.testing.assert_allclose(rewards, method.reward(s, s1), rtol=1e-5, atol=1e-6)
    assert not np.allclose(rewards, 1.0)  # CartPole's own reward is 1 per step


def test_same_seed_same_run_on_cpu(tiny_data, tmp_path):
    def run(name, seed=0):
        train(gaifo_config("AbcoMaze3x3-v0", tiny_data, tmp_path / name, seed=seed))
        rows = [json.loads(x) for x in (tmp_path / name / "metrics.jsonl").read_text()
                .splitlines()]  # fmt: skip
        final = json.loads((tmp_path / name / "final.json").read_text())
        params = torch.load(tmp_path / name / "checkpoint.pt", weights_only=False)["method"]
        drop = ("seconds",)
        return ([{k: v for k, v in r["train"].items() if not k.startswith(drop)} for r in rows],
                {k: v for k, v in final.items() if k not in ("seconds", "figures")}, params)

    first, second = run("a"), run("b")
    assert first[0] == second[0] and first[1] == second[1]
    for part in ("policy", "discriminator"):
        for key, value in first[2][part].items():
            assert torch.equal(value, second[2][part][key]), (part, key)
    other = run("c", seed=1)
    assert any(not torch.equal(v, other[2]["policy"][k]) for k, v in first[2]["policy"].items())


# CartPole: linear schedules; Acrobot: VecNormalize (whole episodes: capped ones score nothing)
@pytest.mark.parametrize(("env_id", "cap"), [("CartPole-v1", 30), ("Acrobot-v1", None)])
def test_a_resumed_run_ends_as_an_uninterrupted_one_and_reloads(env_id, cap, tiny_data,
                                                                tmp_path):  # fmt: skip
    whole = train(gaifo_config(env_id, tiny_data, tmp_path / "whole", eval_max_steps=cap))
    cfg = gaifo_config(env_id, tiny_data, tmp_path / "cut", eval_max_steps=cap)
    assert train(cfg, stop_after=1) is None
    resumed = train(cfg)
    assert resumed["episodes"] == whole["episodes"]
    assert resumed["interactions"] == whole["interactions"]
    # the run folder's policy (abco play, load_policy) acts as the trained one did
    assert load_policy(tmp_path / "whole").evaluate()["episodes"] == whole["episodes"]


def test_unknown_or_bad_options_are_config_errors(tiny_data, tmp_path):
    with pytest.raises(ConfigError, match="unknown gaifo option"):
        make_method("CartPole-v1", tiny_data, tmp_path, n_step=8)
    with pytest.raises(ConfigError, match="--gaifo-reward must be one of logit, gail, log_d, "
                                          "got 'wasserstein'"):  # fmt: skip
        make_method("CartPole-v1", tiny_data, tmp_path, reward="wasserstein")


@pytest.mark.parametrize(("given", "message"), [
    ({"n_steps": 0}, "--gaifo-n-steps must be >= 1, got 0"),
    ({"batch_size": 2.5}, "--gaifo-batch-size must be an integer, got 2.5"),
    ({"rl_steps": True}, "--gaifo-rl-steps must be an integer, got True"),
    ({"learning_rate": 0.0}, "--gaifo-learning-rate must be > 0.0, got 0.0"),
    ({"gamma": float("nan")}, "--gaifo-gamma must be a finite number, got nan"),
    ({"d_lr": None}, "--gaifo-d-lr must be set, got null"),
    ({"net_arch": 64}, "--gaifo-net-arch must be a list, got 64"),
    ({"net_arch": [64, 0]}, r"--gaifo-net-arch must be a list of integers >= 1, got \[64, 0\]"),
])  # fmt: skip
def test_options_are_checked_and_named_as_their_flags(given, message):
    with pytest.raises(ConfigError, match=message):
        GAIfOOptions.for_run(RunConfig(env="CartPole-v1", method="gaifo", method_options=given))


def test_options_resolve_common_then_zoo_then_kind_then_env_then_user():
    def run(env, **given):
        return GAIfOOptions.for_run(RunConfig(env=env, method="gaifo", method_options=given))

    # every option, in the table's order: SB3's defaults under the Zoo's Acrobot row
    assert run("Acrobot-v1").to_dict() == {**COMMON_OPTIONS, **ZOO_PPO["Acrobot-v1"]}
    assert list(run("Acrobot-v1").to_dict()) == list(COMMON_OPTIONS)
    maze = run("AbcoMaze5x5-v0")
    assert (maze.rl_steps, maze.n_steps) == (GAIFO_DEFAULTS["maze"]["rl_steps"], 128)
    cartpole = run("CartPole-v1")
    assert (cartpole.rl_steps, cartpole.reward, cartpole.n_steps) == (50_000, "gail", 32)
    changed = run("CartPole-v1", reward="logit", n_steps=8, normalize=True)
    assert (changed.reward, changed.n_steps, changed.normalize) == ("logit", 8, True)
    # the defaults' lists are not shared between runs
    run("Acrobot-v1").net_arch.append(1)
    assert run("Acrobot-v1").net_arch == [64, 64] == COMMON_OPTIONS["net_arch"]


def test_options_are_flags_of_their_own_with_the_gaifo_prefix():
    parser = argparse.ArgumentParser()
    add_field_options(parser, GAIfOOptions, unset_defaults=True, prefix=GAIfOOptions.flag_prefix)
    args = parser.parse_args(["--gaifo-batch-size", "32", "--gaifo-reward", "log_d"])
    assert (args.batch_size, args.reward, args.rl_steps) == (32, "log_d", None)
    text = parser.format_help()
    assert "--gaifo-rl-steps" in text and "--gaifo-d-batch-size" in text
    assert " --batch-size" not in text and " --lr" not in text  # the run config's own flags


def test_the_resolved_options_are_the_runs_method_options(tiny_data, tmp_path):
    cfg = resolve_config(gaifo_config("CartPole-v1", tiny_data, tmp_path))
    assert cfg.method_options == {**COMMON_OPTIONS, **ZOO_PPO["CartPole-v1"],
                                  **GAIFO_DEFAULTS["CartPole-v1"], **TINY}  # fmt: skip


def test_options_and_method_modules_import_without_torch_or_sb3():
    """options.py needs neither torch nor SB3; method.py (the registry imports it) needs no SB3
    until a run starts, and then says what to install."""
    code = (
        "import sys\n"
        "import abco_train.methods.gaifo.options\n"
        "assert 'torch' not in sys.modules and 'stable_baselines3' not in sys.modules\n"
        "sys.modules['stable_baselines3'] = None\n"
        "from abco_train.config.run import ConfigError\n"
        "from abco_train.methods.gaifo.method import GAIfO\n"
        "try:\n"
        "    GAIfO.defaults('gaifo')\n"
        "except ConfigError as exc:\n"
        "    print(exc)\n"
    )  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout  # fmt: skip
    assert 'pip install "abco[rl]"' in out


def test_without_stable_baselines3_the_error_says_what_to_install(tiny_data, tmp_path,
                                                                 monkeypatch):  # fmt: skip
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # import raises ImportError
    with pytest.raises(ConfigError, match=r"pip install \"abco\[rl\]\""):
        resolve_config(gaifo_config("CartPole-v1", tiny_data, tmp_path))
