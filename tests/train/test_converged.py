"""The converged schedule: a fit stops when its held-out score stops improving (never before
its minimum of updates, never after its maximum; a loss by a relative gain) and keeps its best
weights; the held-out splits are fixed by the seed; runs of the BCO family's variants and of
LAPO, ILPO and DILO train with it end to end, and a resumed LAPO run equals an uninterrupted one."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from train_testing import tiny_config

from abco_train.harness.loop import train
from abco_train.methods.bco.converged import Schedule, expert_split, fit_converged
from abco_train.methods.converged import converge


def _problem(n: int = 256) -> tuple[torch.nn.Module, torch.Tensor, torch.Tensor]:
    torch.manual_seed(0)
    x = torch.randn(n, 2)
    y = (x[:, 0] > 0).long()  # separable: a linear net gets there fast
    return torch.nn.Linear(2, 2), x, y


def _fit(net, x, y, score, schedule):
    opt = torch.optim.Adam(net.parameters(), lr=0.05)
    return fit_converged(net, opt, lambda idx: (x[idx],), y, score, schedule, 32,
                         np.random.default_rng(0))  # fmt: skip


def test_a_fit_stops_once_its_score_stops_improving_and_keeps_its_best_weights():
    net, x, y = _problem()
    scores = iter([0.5, 0.7, 0.9, 0.8, 0.8, 0.8] + [0.1] * 100)
    seen = []

    def score() -> float:
        seen.append({k: v.clone() for k, v in net.state_dict().items()})
        return next(scores)

    out = _fit(net, x, y, score, Schedule(check_updates=10, patience_checks=3, min_updates=1,
                                          max_updates=10_000))  # fmt: skip
    assert out["updates"] == 60 and out["best"] == 0.9  # three checks after the best, then out
    assert all(torch.equal(net.state_dict()[k], seen[2][k]) for k in seen[2])


@pytest.mark.parametrize(("patience", "low", "high", "expected"), [
    (1, 200, 10_000, 200),  # impatient, but not before the minimum
    (100, 1, 35, 35),  # patient: the maximum ends it, part-way through a window
])  # fmt: skip
def test_the_minimum_and_maximum_of_updates_hold(patience, low, high, expected):
    net, x, y = _problem()
    out = _fit(net, x, y, lambda: 0.5, Schedule(10, patience, low, high))  # never better
    assert out["updates"] == expected


def test_the_expert_split_is_the_seeds_own():
    train_a, held_a = expert_split(100, seed=3)
    train_b, held_b = expert_split(100, seed=3)
    assert np.array_equal(held_a, held_b) and len(held_a) == 10
    assert not np.array_equal(held_a, expert_split(100, seed=4)[1])
    assert sorted([*train_a, *held_a]) == list(range(100))
    assert len(expert_split(1, seed=0)[1]) == 0  # one transition: nothing to hold out


@pytest.mark.parametrize(("env", "method"), [
    ("CartPole-v1", "bc"), ("CartPole-v1", "bco"), ("CartPole-v1", "abco"),
    ("AbcoMaze3x3-v0", "iupe"),
])  # fmt: skip
def test_runs_train_to_convergence_end_to_end(env, method, tiny_data, tmp_path):
    options = {"schedule": "converged", "check_updates": 5, "patience_checks": 2,
               "min_fit_updates": 10, "max_fit_updates": 60}  # fmt: skip
    cfg = tiny_config(env, method, tiny_data, tmp_path / method,
                      method_options=options, iterations=1)  # fmt: skip
    train(cfg)
    rows = [json.loads(line) for line in (tmp_path / method / "metrics.jsonl").open()]
    for row in rows:
        stats = row["train"]
        assert 10 <= stats["policy_updates"] <= 60 and "policy_epochs" not in stats
        assert 0.0 <= stats["policy_held_out_agreement"] <= 1.0
        if method != "bc" and "idm_updates" in stats:
            assert 10 <= stats["idm_updates"] <= 60 and "idm_epochs" not in stats
    assert any("idm_updates" in r["train"] for r in rows) == (method != "bc")


def test_a_loss_counts_as_better_only_by_its_relative_gain():
    net = torch.nn.Linear(1, 1)
    scores = iter([-1.0, -0.995, -0.992, -0.991])  # minus a loss
    schedule = Schedule(check_updates=1, patience_checks=3, min_updates=1, max_updates=100)
    out = converge(lambda n: 0.0, lambda: next(scores), [net], schedule, min_gain=0.01)
    assert out == {"loss": 0.0, "updates": 4.0, "best": -1.0}  # half a percent is not a gain
    scores = iter([-1.0, -0.5, -0.499, -0.498, -0.497])
    out = converge(lambda n: 0.0, lambda: next(scores), [net], schedule, min_gain=0.01)
    assert out["updates"] == 5.0 and out["best"] == -0.5


def _lapo_config(tiny_data, run_dir, **changes):
    options = {"schedule": "converged", "check_updates": 3, "patience_checks": 2,
               "min_fit_updates": 6, "max_fit_updates": 15, "rounds": 2}  # fmt: skip
    cfg = tiny_config("AbcoMaze3x3-v0", "lapo", tiny_data, run_dir, method_options=options,
                      device="cpu", **changes)  # fmt: skip
    return cfg


def test_lapo_trains_each_stage_to_convergence(tiny_data, tmp_path):
    train(_lapo_config(tiny_data, tmp_path / "run"))
    rows = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").open()]
    assert len(rows) == 2
    for row in rows:
        stats = row["train"]
        for count in ("model_steps", "decoder_updates", "policy_steps"):
            assert 6 <= stats[count] <= 15, (count, stats[count])
        assert stats["model_held_out"] < 0 and stats["policy_held_out"] < 0  # minus losses
        assert 0.0 <= stats["decoder_held_out_accuracy"] <= 1.0


def test_a_resumed_converged_lapo_run_equals_an_uninterrupted_one(tiny_data, tmp_path):
    def numbers(run_dir):
        rows = [json.loads(line) for line in (run_dir / "metrics.jsonl").open()]
        return [(r["train"], r["eval"]) for r in rows]

    train(_lapo_config(tiny_data, tmp_path / "straight"))
    resumed = _lapo_config(tiny_data, tmp_path / "resumed")
    assert train(resumed, stop_after=1) is None
    train(resumed)
    assert numbers(tmp_path / "straight") == numbers(tmp_path / "resumed")


@pytest.mark.parametrize("env", ["CartPole-v1", "AbcoMaze3x3-v0"])  # G and pi jointly; in turn
def test_ilpo_trains_its_latent_model_to_convergence(env, tiny_data, tmp_path):
    options = {"schedule": "converged", "check_updates": 3, "patience_checks": 2,
               "min_fit_updates": 6, "max_fit_updates": 15, "remap_steps": 20}  # fmt: skip
    cfg = tiny_config(env, "ilpo", tiny_data, tmp_path / "run", method_options=options,
                      device="cpu")  # fmt: skip
    train(cfg)
    first = json.loads((tmp_path / "run" / "metrics.jsonl").open().readline())["train"]
    counts = ["train_steps"] + (["policy_steps"] if env.startswith("Abco") else [])
    for count in counts:
        assert 6 <= first[count] <= 15, (count, first[count])
    assert first["held_out_loss_min"] >= 0 and first["held_out_loss_exp"] >= 0


def test_dilo_trains_its_utility_then_its_policy_to_convergence(tiny_data, tmp_path):
    options = {"schedule": "converged", "check_updates": 3, "patience_checks": 2,
               "min_fit_updates": 6, "max_fit_updates": 15, "rounds": 1}  # fmt: skip
    cfg = tiny_config("CartPole-v1", "dilo", tiny_data, tmp_path / "run", method_options=options,
                      device="cpu")  # fmt: skip
    train(cfg)
    stats = json.loads((tmp_path / "run" / "metrics.jsonl").open().readline())["train"]
    assert 6 <= stats["value_steps"] <= 15 and 6 <= stats["policy_steps"] <= 15
    assert np.isfinite(stats["value_held_out"]) and stats["policy_held_out"] <= 0
