"""Aggregates over tasks with different numbers of runs: every run kept, every task weighing
the same, and the rectangular case's numbers where the runs are equal."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import trim_mean

from abco_train.report import aggregates, balanced, ranking


def _columns(x: np.ndarray) -> list[np.ndarray]:
    return [x[:, t] for t in range(x.shape[1])]


@pytest.mark.parametrize("runs", [4, 8, 12])
def test_equal_runs_give_the_rectangular_statistics(runs: int) -> None:
    x = np.random.default_rng(runs).random((runs, 5)) * 1.4 - 0.2
    y = np.random.default_rng(runs + 1).random((runs, 5))
    assert balanced.iqm(_columns(x)) == pytest.approx(trim_mean(x.ravel(), 0.25))
    assert balanced.mean(_columns(x)) == pytest.approx(x.mean())
    assert balanced.optimality_gap(_columns(x)) == pytest.approx(np.maximum(1 - x, 0).mean())
    assert balanced.probability_of_improvement(_columns(x), _columns(y)) == pytest.approx(
        aggregates.probability_of_improvement(x, y))
    taus = np.linspace(0, 1, 11)
    assert balanced.profile(_columns(x), taus) == pytest.approx(
        [(x > tau).mean() for tau in taus])


def test_every_task_weighs_the_same_however_many_runs_it_has() -> None:
    many, few = np.full(20, 1.0), np.zeros(10)
    assert balanced.mean([many, few]) == pytest.approx(0.5)  # pooled runs would give 2/3
    assert balanced.optimality_gap([many, few]) == pytest.approx(0.5)
    assert balanced.profile([many, few], np.array([0.5]))[0] == pytest.approx(0.5)
    # the middle half of the weight: a quarter of each task's, values 0 and 1 alike
    assert balanced.iqm([many, few]) == pytest.approx(0.5)


def test_a_grid_with_fewer_seeds_on_some_tasks_keeps_every_run(tmp_path) -> None:
    rl = aggregates.load_rliable()[0]
    if rl is None:
        pytest.skip("rliable is not installed")
    rng = np.random.default_rng(0)
    scores = {m: {"classic": dict(enumerate(rng.random(20) * 0.5 + shift)),
                  "maze": dict(enumerate(rng.random(10) * 0.5 + shift))}
              for m, shift in (("bco", 0.5), ("abco", 0.0))}  # fmt: skip
    ranked = ranking.compute(scores, ["classic", "maze"], rl, reps=200)
    assert ranked.balanced and ranked.runs == {"bco": [20, 10], "abco": [20, 10]}
    for m, by_task in scores.items():
        expected = np.mean([np.mean(list(by_task[t].values())) for t in ("classic", "maze")])
        point, low, high = ranked.mean[m]
        assert point == pytest.approx(expected) and low < point < high
        assert ranked.profile_cis[m].shape == (2, len(ranked.taus))
    p, low, high = ranked.pairs[("bco", "abco")]
    assert p == 1.0 and ranking.verdict(low, high) == "better"
    lines, _ = ranking.section(scores, ["classic", "maze"], tmp_path, {}, [], reps=50)
    assert any(line.startswith("- runs per task differ") for line in lines)
    assert "| 10-20 |" in "\n".join(lines)


def test_a_task_with_one_run_is_held_fixed_in_the_bootstrap() -> None:
    rl = aggregates.load_rliable()[0]
    if rl is None:
        pytest.skip("rliable is not installed")
    scores = {"bco": {"a": {0: 0.2, 1: 0.4, 2: 0.9}, "b": {0: 0.5}},
              "abco": {"a": {0: 0.1}, "b": {0: 0.3}}}  # every sample of abco a single run
    ranked = ranking.compute(scores, ["a", "b"], rl, reps=100)
    assert ranked.runs == {"bco": [3, 1], "abco": [1, 1]}
    assert ranked.mean["abco"] == pytest.approx((0.2, 0.2, 0.2))
    point, low, high = ranked.mean["bco"]
    assert low <= point <= high and low < high
