"""IUPE (exploration rollouts) and the interaction counts every run records."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from train_testing import tiny_config

import abco_envs
from abco_train.harness.loop import train
from abco_train.harness.runtime import seed_everything
from abco_train.harness.training_data import load_training_data
from abco_train.methods.base import INTERACTION_KINDS, Method
from abco_train.methods.iupe import IUPE
from abco_train.methods.registry import resolve_config

ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)


@pytest.mark.parametrize("env_id", ENVS)
def test_iupe_runs_on_every_env_and_counts_its_rollouts(env_id, tiny_data, tmp_path):
    final = train(tiny_config(env_id, "iupe", tiny_data, tmp_path))
    key = "train/paper" if env_id in abco_envs.MAZE_IDS else "episodes"
    assert np.isfinite(final[key]["performance"])
    counts = final["interactions"]
    assert set(counts) == set(INTERACTION_KINDS)
    assert counts["pre_demonstration"] > 0 and counts["post_demonstration"] > 0
    assert counts["rl"] == counts["remapping"] == 0
    rows = [json.loads(x) for x in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    # iteration 0's exploration runs feed iteration 1; the last iteration's feed nothing
    assert rows[0]["interactions"]["post_demonstration"] == counts["post_demonstration"]


def test_iupe_explores_by_sampling_the_policy_softmax(tiny_data, tmp_path):
    cfg = resolve_config(tiny_config("CartPole-v1", "iupe", tiny_data, tmp_path, device="cpu"))
    method = IUPE(cfg, load_training_data(cfg), seed_everything(0))
    head = [m for m in method.policy.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():  # a policy with known action probabilities: 0.25 / 0.75
        head.weight.zero_()
        head.bias.copy_(torch.log(torch.tensor([0.25, 0.75])))
    obs = np.zeros((4000, 4), dtype=np.float32)
    start = method.rng.bit_generator.state
    explored = method.explore(obs)
    assert abs(explored.mean() - 0.75) < 0.03  # sampled, not the argmax (always 1)
    assert (method.act(obs) == 1).all()
    method.rng.bit_generator.state = start  # the run's generator fixes every draw
    assert (method.explore(obs) == explored).all()


def test_bc_counts_nothing_and_bco_only_its_pre_demonstrations(tiny_data, tmp_path):
    bc = train(tiny_config("CartPole-v1", "bc", tiny_data, tmp_path / "bc"))
    assert bc["interactions"] == dict.fromkeys(INTERACTION_KINDS, 0)
    bco = train(tiny_config("CartPole-v1", "bco", tiny_data, tmp_path / "bco"))
    assert bco["interactions"]["pre_demonstration"] > 0
    assert bco["interactions"]["post_demonstration"] == 0


def test_count_rejects_an_unknown_kind(tiny_data, tmp_path):
    cfg = resolve_config(tiny_config("CartPole-v1", "bc", tiny_data, tmp_path))
    cfg = cfg.replace(method_options={})  # the probe below has no options

    class Probe(Method):
        def train_iteration(self, iteration):
            return {}

        def act(self, obs):
            return np.zeros(len(obs), dtype=np.int64)

        def state_dict(self):
            return {}

        def load_state_dict(self, state):
            pass

    probe = Probe(cfg, load_training_data(cfg), np.random.default_rng(0))
    probe.count("rl", 5)
    assert probe.interactions["rl"] == 5
    with pytest.raises(ValueError, match="unknown interaction kind 'evaluation'"):
        probe.count("evaluation", 1)
