"""Statistics over seeds: mean, interquartile mean and bootstrap confidence intervals.

One (env, method, evaluation) cell of a grid is summarised over its seeds:

* point estimates: the mean and the IQM (mean of the middle 50%: ``floor(n/4)`` values cut at
  each end, as ``scipy.stats.trim_mean(x, 0.25)``) of the per-seed scores;
* 95% confidence interval: a two-stage percentile bootstrap (numpy only, seeded, 10,000
  replicates): each replicate draws ``n`` seeds with replacement and, where ``final.json``
  holds per-episode values (``episode_returns`` / ``episode_performance``), redraws each drawn
  seed's episodes with replacement; the statistic (mean or IQM) of the replicate's per-seed
  scores gives the bootstrap distribution and its 2.5th and 97.5th percentiles the interval.
  Without per-episode values (the trainer's ``final.json`` today) it resamples seeds only.

Example:
    >>> iqm([1.0, 2.0, 3.0, 4.0, 100.0])
    3.0
    >>> lo, hi = bootstrap_ci([np.array([1.0]), np.array([3.0])])
    >>> (lo, hi)
    (1.0, 3.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["CellStats", "bootstrap_ci", "cell_stats", "iqm", "N_BOOT", "BOOT_SEED"]

N_BOOT = 10_000
BOOT_SEED = 0


def iqm(values: Sequence[float] | np.ndarray) -> float:
    """Interquartile mean: the mean after cutting ``floor(n / 4)`` values at each end."""
    x = np.sort(np.asarray(values, dtype=np.float64))
    cut = int(np.floor(0.25 * len(x)))
    return float(x[cut : len(x) - cut].mean())


def _iqm_rows(x: np.ndarray) -> np.ndarray:
    x = np.sort(x, axis=1)
    cut = int(np.floor(0.25 * x.shape[1]))
    return x[:, cut : x.shape[1] - cut].mean(axis=1)


def bootstrap_ci(
    groups: Sequence[np.ndarray], statistic: str = "mean", n_boot: int = N_BOOT,
    confidence: float = 0.95, seed: int = BOOT_SEED,
) -> tuple[float, float]:  # fmt: skip
    """Two-stage percentile bootstrap interval of ``statistic`` over seeds.

    Args:
        groups: One array per seed: its episodes' values, or its one score.
        statistic: ``"mean"`` or ``"iqm"`` of the per-seed means.
        n_boot: Replicates.
        confidence: Coverage of the interval.
        seed: Seed of the resampling.
    """
    groups = [np.asarray(g, dtype=np.float64).reshape(-1) for g in groups]
    n = len(groups)
    if n == 0:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, n, size=(n_boot, n))  # stage 1: seeds with replacement
    per_seed = np.empty((n_boot, n))
    for s, g in enumerate(groups):
        mask = pick == s
        if len(g) == 1:
            per_seed[mask] = g[0]
        else:  # stage 2: that seed's episodes with replacement
            k = int(mask.sum())
            per_seed[mask] = g[rng.integers(0, len(g), size=(k, len(g)))].mean(axis=1)
    stats = per_seed.mean(axis=1) if statistic == "mean" else _iqm_rows(per_seed)
    alpha = (1.0 - confidence) / 2
    lo, hi = np.quantile(stats, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


@dataclass
class CellStats:
    """Mean and IQM over seeds, each with its bootstrap interval."""

    n: int
    mean: float
    ci: tuple[float, float]
    iqm: float
    iqm_ci: tuple[float, float]


def cell_stats(groups: Sequence[np.ndarray]) -> CellStats | None:
    """:class:`CellStats` of per-seed groups (``None`` when there are none)."""
    if not groups:
        return None
    scores = np.array([np.mean(g) for g in groups])
    return CellStats(len(groups), float(scores.mean()), bootstrap_ci(groups), iqm(scores),
                     bootstrap_ci(groups, "iqm"))  # fmt: skip
