"""Aggregates over tasks with different numbers of runs, every task weighing the same.

A track may test its costly tasks on fewer seeds than the others (a task's own
``test_seeds``). rliable's estimators take one (runs x tasks) matrix per method, which would
keep only the fewest runs of any task; here every run is kept and each task weighs the
same: a run of a task with ``n`` runs weighs ``1 / (tasks * n)``.

* mean: the mean over tasks of each task's mean;
* IQM: the weighted interquartile mean, the mean of the middle half of the weight (a run
  straddling a quartile counts in part): with equal runs per task and runs times tasks a
  multiple of 4, rliable's IQM exactly;
* optimality gap: the weighted mean of ``max(gamma - score, 0)``;
* performance profile: the weight of the runs scoring above each threshold;
* probability of improvement: P(X > Y) per task (ties half), averaged over tasks.

Intervals: 95% percentile bootstrap by ``scipy.stats.bootstrap``, each task's runs (and each
method's, for a pair) resampled on their own: the stratified (independent) bootstrap of the
rectangular case.

Example:
    >>> columns = [np.array([0.0, 1.0]), np.array([0.2, 0.4, 0.6, 0.8])]
    >>> float(mean(columns)), float(iqm([np.arange(8.0)]))
    (0.5, 3.5)
    >>> float(probability_of_improvement(columns, [np.array([0.5]), np.array([0.5])]))
    0.5
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["Columns", "mean", "iqm", "optimality_gap", "profile",
           "probability_of_improvement", "interval"]  # fmt: skip

#: One method's scores: one array of runs per task, in the tasks' order.
Columns = Sequence[np.ndarray]


def _weighted(columns: Columns) -> tuple[np.ndarray, np.ndarray]:
    """Every run's score and weight (``1 / (tasks * runs of its task)``), by score."""
    values = np.concatenate([np.asarray(c, dtype=np.float64) for c in columns])
    weights = np.concatenate([np.full(len(c), 1.0 / (len(columns) * len(c))) for c in columns])
    order = np.argsort(values, kind="stable")
    return values[order], weights[order]


def mean(columns: Columns) -> float:
    """The mean over tasks of each task's mean score."""
    return float(np.mean([np.mean(c) for c in columns]))


def iqm(columns: Columns) -> float:
    """The weighted interquartile mean: the runs' mean over the middle half of the weight."""
    values, weights = _weighted(columns)
    upper = np.cumsum(weights)
    lower = upper - weights
    inside = np.clip(np.minimum(upper, 0.75) - np.maximum(lower, 0.25), 0.0, None)
    return float(np.sum(values * inside) / np.sum(inside))


def optimality_gap(columns: Columns, gamma: float = 1.0) -> float:
    """The weighted mean of ``max(gamma - score, 0)``: how far the runs fall short."""
    values, weights = _weighted(columns)
    return float(np.sum(np.maximum(gamma - values, 0.0) * weights))


def profile(columns: Columns, taus: np.ndarray) -> np.ndarray:
    """The weight of the runs scoring above each of ``taus``."""
    values, weights = _weighted(columns)
    return ((values[:, None] > np.asarray(taus)[None]) * weights[:, None]).sum(0)


def probability_of_improvement(x: Columns, y: Columns) -> float:
    """P(a run of X beats a run of Y on the same task), ties half, averaged over tasks."""
    per_task = []
    for a, b in zip(x, y):
        d = np.asarray(a, dtype=np.float64)[:, None] - np.asarray(b, dtype=np.float64)[None]
        per_task.append(np.mean((d > 0) + 0.5 * (d == 0)))
    return float(np.mean(per_task))


def interval(statistic: Callable[..., np.ndarray], samples: Sequence[np.ndarray], reps: int,
             seed: int) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The 95% percentile-bootstrap interval ``(low, high)`` of the vector ``statistic`` of
    ``samples``, each sample resampled on its own (``seed``: the bootstrap's generator). A
    sample of one run resamples to itself: it is held fixed (scipy draws from samples of two
    or more); with no other sample the interval is the point.

    Example:
        >>> low, high = interval(lambda a, b: np.array([mean([a, b])]),
        ...                      [np.array([0.5]), np.array([0.0, 1.0])], reps=200, seed=0)
        >>> float(low[0]), float(high[0])
        (0.25, 0.75)
    """
    from scipy.stats import bootstrap

    data = [np.asarray(s, dtype=np.float64) for s in samples]
    drawn_at = [i for i, s in enumerate(data) if len(s) > 1]
    if not drawn_at:
        point = np.atleast_1d(statistic(*data))
        return point, point

    def with_fixed(*drawn: np.ndarray) -> np.ndarray:
        full = list(data)
        for i, sample in zip(drawn_at, drawn):
            full[i] = sample
        return np.atleast_1d(statistic(*full))

    result = bootstrap(tuple(data[i] for i in drawn_at), with_fixed, n_resamples=reps,
                       method="percentile", vectorized=False,
                       rng=np.random.default_rng(seed))  # fmt: skip
    interval = result.confidence_interval
    return np.atleast_1d(interval.low), np.atleast_1d(interval.high)
