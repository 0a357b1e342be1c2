"""The report's statistics on hand-made numbers: IQM, bootstrap intervals, paper data."""

from __future__ import annotations

import numpy as np
import pytest

from abco_train.report import published as paper
from abco_train.report import stats
from abco_train.report import write as report


def test_iqm_cuts_a_quarter_at_each_end() -> None:
    assert stats.iqm([1.0, 2.0, 3.0, 4.0, 100.0]) == 3.0  # floor(5/4) = 1 cut per end
    assert stats.iqm([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 100.0]) == pytest.approx(4.5)
    assert stats.iqm([2.0, 4.0]) == 3.0  # fewer than 4 values: the mean
    assert stats.iqm([-5.0, 1.0, 1.0, 50.0]) == 1.0


def test_bootstrap_over_seeds_only() -> None:
    lo, hi = stats.bootstrap_ci([np.array([1.0]), np.array([3.0])])
    assert (lo, hi) == (1.0, 3.0)  # replicate means 1, 2, 3 with prob 1/4, 1/2, 1/4
    values = [np.array([v]) for v in (0.2, 0.4, 0.5, 0.9, 1.0)]
    lo, hi = stats.bootstrap_ci(values)
    assert 0.2 <= lo < 0.6 < hi <= 1.0
    assert stats.bootstrap_ci(values) == (lo, hi)  # seeded
    assert stats.bootstrap_ci([np.array([7.0])] * 3) == (7.0, 7.0)
    lo, hi = stats.bootstrap_ci(values, "iqm")
    assert lo <= stats.iqm([0.2, 0.4, 0.5, 0.9, 1.0]) <= hi


def test_two_stage_bootstrap_resamples_episodes_within_seeds() -> None:
    rng = np.random.default_rng(1)
    # identical seed means, noisy episodes: only the inner stage makes the interval wide
    groups = [g - g.mean() + 0.5 for g in (rng.normal(0, 1, 50) for _ in range(4))]
    lo, hi = stats.bootstrap_ci(groups)
    assert lo < 0.5 < hi
    assert hi - lo == pytest.approx(2 * 1.96 / np.sqrt(200), rel=0.3)  # ~ pooled standard error
    lo1, hi1 = stats.bootstrap_ci([np.array([g.mean()]) for g in groups])
    assert lo1 == pytest.approx(0.5) and hi1 == pytest.approx(0.5)


def test_cell_stats_bounds_contain_the_estimates() -> None:
    s = stats.cell_stats([np.array([v]) for v in (0.91, 0.95, 0.97, 0.99, 0.62)])
    assert s is not None and s.n == 5
    assert s.mean == pytest.approx(0.888)
    assert s.iqm == pytest.approx((0.91 + 0.95 + 0.97) / 3)
    assert s.ci[0] <= s.mean <= s.ci[1]
    assert s.iqm_ci[0] <= s.iqm <= s.iqm_ci[1]
    assert stats.cell_stats([]) is None


def test_paper_numbers() -> None:
    assert paper.PAPER_TABLE1["abco"]["AbcoMaze5x5-v0"] == (0.960, 0.932)
    assert paper.PAPER_TABLE1["bco-alpha"]["MountainCar-v0"] == (0.948, -150.0)
    assert report.GOALS["aer"] == {"CartPole-v1": 500.0, "Acrobot-v1": -77.9,
                                   "MountainCar-v0": -132.3, "AbcoMaze3x3-v0": 0.908,
                                   "AbcoMaze5x5-v0": 0.932, "AbcoMaze10x10-v0": 0.784}
    assert set(paper.PAPER_TABLE2) == set(report.TABLE2_METHODS) - {"bco-alpha-torabi"}
    from abco_train.methods.bco.family import VARIANTS

    coming = {"ilpo", "gaifo"}  # being written; their names are fixed
    assert set(report.TABLE1_METHODS) | set(report.TABLE2_METHODS) <= set(VARIANTS) | {
        "iupe"} | coming
    assert list(report.TABLE1_METHODS) == ["bc", "bco", "bco-alpha", "abco", "iupe", "ilpo",
                                           "gaifo"]  # fmt: skip
    modern = {"dilo", "lapo"}  # after the paper's tables: the headline's newer methods
    assert set(report.ORDER) == set(report.TABLE1_METHODS) | set(report.TABLE2_METHODS) | modern


def test_published_aer_of_iupe_and_ilpo() -> None:
    assert paper.PUBLISHED_AER["iupe"] == {
        "CartPole-v1": 500.0, "Acrobot-v1": -78.1, "MountainCar-v0": -130.7,
        "AbcoMaze3x3-v0": 0.927, "AbcoMaze5x5-v0": 0.971, "AbcoMaze10x10-v0": 0.981}
    assert paper.PUBLISHED_AER["ilpo"] == {
        "CartPole-v1": 500.0, "Acrobot-v1": -85.3, "MountainCar-v0": -167.0,
        "AbcoMaze3x3-v0": -0.026, "AbcoMaze5x5-v0": -0.059, "AbcoMaze10x10-v0": -0.020}
    assert paper.published("ilpo", "AbcoMaze10x10-v0") == (None, -0.020)
    assert paper.published("gaifo", "Acrobot-v1") is None
    assert report.GOALS["published_aer"] is paper.PUBLISHED_AER
    assert report.GOALS["wall_s"] == 4 * 3600.0  # the seven-method grid
