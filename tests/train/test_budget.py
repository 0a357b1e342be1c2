"""``--budget``: no run spends more environment interactions than it is given, a budget that
binds stops training (and says so), a method that counts past it fails, none changes nothing."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from train_testing import tiny_config

import abco_train.methods.ilpo.method as ilpo_method
from abco_train.harness.loop import train
from abco_train.harness.rollouts import rollout
from abco_train.methods.base import INTERACTION_KINDS
from abco_train.methods.bco.family import BCOFamily

CARTPOLE, MAZE = "CartPole-v1", "AbcoMaze3x3-v0"
IFO_METHODS = ("bco", "bco-alpha", "abco", "iupe", "ilpo")
#: ILPO's tiny schedule (tests/train/test_ilpo.py): 24 remapping steps in 4 slots a round.
ILPO_TINY = {"train_steps": 4, "remap_steps": 24, "remap_envs": 4, "remap_epochs": 2}


def _run(env_id, method, tiny_data, run_dir, **changes):
    """A tiny run of 3 iterations (``--iterations 2``): its ``final.json`` and metrics rows."""
    if method == "ilpo":
        options = {**ILPO_TINY, **({"policy_steps": 4} if env_id == MAZE else {})}
        changes.setdefault("method_options", options)
    final = train(tiny_config(env_id, method, tiny_data, run_dir, iterations=2, device="cpu",
                              **changes))  # fmt: skip
    assert final is not None  # a finished run's record
    return final, _rows(run_dir)


def _rows(run_dir):
    return [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]


def _spent(counts):
    return sum(counts.get(k, 0) for k in INTERACTION_KINDS)


# -- no budget, or one that does not bind: nothing changes -------------------------------------

#: Interactions of the tiny runs without a budget (as before budgets existed): pre-demonstrations
#: (CartPole: the 300 transitions of the tiny dataset; maze: 35), post-demonstrations (the
#: rollouts of iterations 0 and 1; the last iteration's train nothing) and remapping steps.
NO_BUDGET = {
    (CARTPOLE, "bco"): {"pre_demonstration": 300},
    (CARTPOLE, "bco-alpha"): {"pre_demonstration": 300, "post_demonstration": 36},
    (CARTPOLE, "abco"): {"pre_demonstration": 300, "post_demonstration": 36},
    (CARTPOLE, "iupe"): {"pre_demonstration": 300, "post_demonstration": 51},
    (CARTPOLE, "ilpo"): {"remapping": 72},
    (MAZE, "bco"): {"pre_demonstration": 35},
    (MAZE, "bco-alpha"): {"pre_demonstration": 35, "post_demonstration": 20},
    (MAZE, "abco"): {"pre_demonstration": 35, "post_demonstration": 20},
    (MAZE, "iupe"): {"pre_demonstration": 35, "post_demonstration": 27},
    (MAZE, "ilpo"): {"remapping": 72},
}


@pytest.mark.parametrize(("env_id", "method"), sorted(NO_BUDGET))
def test_no_budget_and_a_loose_one_change_nothing(env_id, method, tiny_data, tmp_path):
    free, free_rows = _run(env_id, method, tiny_data, tmp_path / "free")
    assert free["interactions"] == {**dict.fromkeys(INTERACTION_KINDS, 0),
                                    **NO_BUDGET[env_id, method]}  # fmt: skip
    assert "stopped" not in free and not any("budget_left" in r for r in free_rows)
    loose, loose_rows = _run(env_id, method, tiny_data, tmp_path / "loose", budget=10_000)
    assert loose["interactions"] == free["interactions"]
    assert "stopped" not in loose
    assert [r["eval"] for r in loose_rows] == [r["eval"] for r in free_rows]
    assert [r["interactions"] for r in loose_rows] == [r["interactions"] for r in free_rows]
    assert all(r["budget_left"] == 10_000 - _spent(r["interactions"]) for r in loose_rows)


# -- a budget is never exceeded ----------------------------------------------------------------

#: Budgets that bind at every stage: within the pre-demonstrations, within the first or second
#: post-demonstration rollout (CartPole's: 18 steps, the maze's: 10), within ILPO's remapping.
BUDGETS = {
    (CARTPOLE, "bco"): (1, 150),
    (CARTPOLE, "bco-alpha"): (299, 305, 325),
    (CARTPOLE, "abco"): (100, 310, 330),
    (CARTPOLE, "iupe"): (1, 310, 335),
    (CARTPOLE, "ilpo"): (1, 6, 30, 50),
    (MAZE, "bco"): (20,),
    (MAZE, "bco-alpha"): (36, 40, 50),
    (MAZE, "abco"): (7, 38, 49),
    (MAZE, "iupe"): (37, 45, 55),
    (MAZE, "ilpo"): (5, 26, 49),
}


@pytest.mark.parametrize(("env_id", "method", "budget"),
                         [(e, m, b) for (e, m), bs in sorted(BUDGETS.items()) for b in bs])
def test_a_run_never_spends_more_than_its_budget(env_id, method, budget, tiny_data, tmp_path):
    final, rows = _run(env_id, method, tiny_data, tmp_path, budget=budget)
    assert final["status"] == "ok"
    assert _spent(final["interactions"]) <= budget
    assert all(_spent(r["interactions"]) <= budget for r in rows)
    assert rows[-1]["budget_left"] == budget - _spent(final["interactions"])
    free = NO_BUDGET[env_id, method]
    # pre-demonstrations: at most the budget's worth, every one counted once
    assert final["interactions"]["pre_demonstration"] == min(free.get("pre_demonstration", 0),
                                                             budget)  # fmt: skip
    if budget < _spent(free):  # it binds: all of it is spent (ILPO: but for part of a round)
        assert budget - _spent(final["interactions"]) < (4 if method == "ilpo" else 1)


# -- a budget that binds stops training early, and says so --------------------------------------

#: (env, method, budget, the last iteration trained): the budget ends within the pre-
#: demonstrations (iteration 0 trains on them, its rollout is none), within iteration 0's
#: rollout (iteration 1 trains on it, then stops) or within ILPO's first remapping round.
STOPS = [
    (CARTPOLE, "bco-alpha", 300, 0), (CARTPOLE, "bco-alpha", 310, 1),
    (CARTPOLE, "abco", 50, 0), (CARTPOLE, "iupe", 310, 1), (CARTPOLE, "ilpo", 3, 0),
    (MAZE, "abco", 40, 1), (MAZE, "bco-alpha", 35, 0), (MAZE, "iupe", 36, 1),
    (MAZE, "ilpo", 20, 0),
]  # fmt: skip


@pytest.mark.parametrize(("env_id", "method", "budget", "last"), STOPS)
def test_a_binding_budget_stops_training_and_says_so(env_id, method, budget, last, tiny_data,
                                                    tmp_path):  # fmt: skip
    final, rows = _run(env_id, method, tiny_data, tmp_path, budget=budget)
    assert final["status"] == "ok"
    assert (final["stopped"], final["stopped_after"]) == ("budget", last)
    assert [r["iteration"] for r in rows] == list(range(last + 1))  # no iteration after it
    assert rows[-1]["stopped"] == "budget" and rows[-1]["budget_left"] == 0
    assert not any("stopped" in r for r in rows[:-1])
    assert _spent(final["interactions"]) == budget
    assert np.isfinite(final["episodes" if env_id == CARTPOLE else "train/paper"]["performance"])


def test_a_cut_rollout_is_counted_exactly_and_the_evaluation_is_not_cut(tiny_data, tmp_path):
    """bco-alpha learns from its evaluation runs: the 10 steps left of its budget cut them, it
    counts those 10, and the iteration's evaluation is still that of the whole episodes."""
    free, free_rows = _run(CARTPOLE, "bco-alpha", tiny_data, tmp_path / "free")
    _, rows = _run(CARTPOLE, "bco-alpha", tiny_data, tmp_path / "cut", budget=310)
    assert rows[0]["interactions"]["post_demonstration"] == 10
    assert rows[0]["budget_cut_runs"] >= 1
    assert rows[0]["eval"] == free_rows[0]["eval"]


def test_methods_that_learn_from_no_rollout_evaluate_uncut(tiny_data, tmp_path):
    """bc and bco learn nothing from the evaluation runs: a budget leaves them whole."""
    for method, budget in (("bc", 1), ("bco", 300)):
        free, free_rows = _run(CARTPOLE, method, tiny_data, tmp_path / f"{method}-free")
        spent, rows = _run(CARTPOLE, method, tiny_data, tmp_path / method, budget=budget)
        assert rows[0]["eval"] == free_rows[0]["eval"]
        assert _spent(spent["interactions"]) == (0 if method == "bc" else budget)
        assert "budget_cut_runs" not in rows[0] and "stopped" not in spent


# -- resuming ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("method", "budget"), [("bco-alpha", 330), ("ilpo", 30)])
def test_a_resumed_run_counts_on_from_its_checkpoint(method, budget, tiny_data, tmp_path):
    whole, whole_rows = _run(CARTPOLE, method, tiny_data, tmp_path / "whole", budget=budget)
    run_dir = tmp_path / "resumed"
    cfg = tiny_config(CARTPOLE, method, tiny_data, run_dir, iterations=2, device="cpu",
                      budget=budget, method_options=ILPO_TINY if method == "ilpo" else {})
    assert train(cfg, stop_after=1) is None
    resumed = train(cfg)
    assert resumed is not None and resumed["interactions"] == whole["interactions"]
    assert _spent(resumed["interactions"]) == budget  # it binds in iteration 1 or 2
    assert [r["interactions"] for r in _rows(run_dir)] == [r["interactions"]
                                                           for r in whole_rows]  # fmt: skip


def test_a_run_that_stopped_for_its_budget_resumes_to_its_final_evaluation(tiny_data,
                                                                          tmp_path):  # fmt: skip
    """Killed between its last checkpoint and ``final.json``: it trains no further."""
    first, rows = _run(CARTPOLE, "bco-alpha", tiny_data, tmp_path, budget=310)
    (tmp_path / "final.json").unlink()
    again, again_rows = _run(CARTPOLE, "bco-alpha", tiny_data, tmp_path, budget=310)
    assert again_rows == rows
    assert (again["stopped"], again["stopped_after"]) == ("budget", 1)
    assert again["interactions"] == first["interactions"]


# -- a method that counts past its budget fails ----------------------------------------------


def test_counting_past_the_budget_ends_the_run_over_budget(tiny_data, tmp_path, monkeypatch):
    """An ILPO whose remapping ignores the budget left: its 24 steps are more than 10."""
    steps = ilpo_method.remapping_steps
    monkeypatch.setattr(ilpo_method, "remapping_steps",
                        lambda *args: steps(*args[:7]))  # the limit left out  # fmt: skip
    final, rows = _run(CARTPOLE, "ilpo", tiny_data, tmp_path, budget=10)
    assert (final["status"], final["iteration"]) == ("over_budget", 0)
    assert "over its budget of 10" in final["message"]
    assert not any(isinstance(v, dict) and "performance" in v for v in final.values())
    assert _spent(final["interactions"]) == 0  # the count that would exceed it is not added
    assert rows[-1]["status"] == "over_budget"
    monkeypatch.undo()
    assert _run(CARTPOLE, "ilpo", tiny_data, tmp_path, budget=10)[0] == final  # stored


def test_a_method_over_budget_as_it_starts_ends_the_run_over_budget(tiny_data, tmp_path,
                                                                   monkeypatch):  # fmt: skip
    """A BCO that takes all 300 pre-demonstrations whatever its budget counts them as it is
    built."""
    monkeypatch.setattr(BCOFamily, "budget_left", property(lambda self: None))
    final, _ = _run(CARTPOLE, "bco", tiny_data, tmp_path, budget=100)
    assert final["status"] == "over_budget"
    assert "pre_demonstration" in final["message"]


# -- the rollouts' step budget ---------------------------------------------------------------


def _turn_left(obs):
    return np.zeros(len(obs), dtype=np.int64)


def test_rollout_stops_its_batch_at_max_total_steps():
    whole = rollout(_turn_left, CARTPOLE, episodes=4, seed=3, record=True)
    assert whole.budget_cut is None
    loose = rollout(_turn_left, CARTPOLE, episodes=4, seed=3, record=True,
                    max_total_steps=int(whole.lengths.sum()))  # fmt: skip
    assert loose.budget_cut is not None and not loose.budget_cut.any()
    assert (loose.lengths == whole.lengths).all() and (loose.actions == whole.actions).all()
    cut = rollout(_turn_left, CARTPOLE, episodes=4, seed=3, record=True, max_total_steps=10)
    assert int(cut.lengths.sum()) == 10 and cut.budget_cut is not None
    assert cut.budget_cut.any() and not cut.successes[cut.budget_cut].any()
    assert (cut.lengths <= whole.lengths).all()
    assert cut.actions is not None and len(cut.actions) == 10  # what is recorded is counted
    assert cut.observations is not None and len(cut.observations) == 10 + 4
    # the win rate counts only the runs that ended on their own
    one_ended = dataclasses.replace(cut, budget_cut=np.array([False, True, True, True]),
                                    successes=np.array([True, False, False, False]))
    assert one_ended.win_rate == 1.0 and cut.win_rate == 0.0  # none of cut's ended
    with pytest.raises(ValueError, match="max_total_steps"):
        rollout(_turn_left, CARTPOLE, episodes=2, max_total_steps=0)
