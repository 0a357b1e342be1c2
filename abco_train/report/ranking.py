"""The benchmark track over its tasks: aggregates of the IfO methods, and which ones it tells
apart.

Each IfO method (:data:`~abco_train.report.headline.IFO_METHODS`) with scored
runs on every task enters as a (runs x tasks) matrix of its runs' headline scores. With
``rliable`` (``pip install "abco[stats]"``), as the paper track's aggregates:

* IQM, mean and optimality gap (``rliable.metrics.aggregate_iqm`` / ``aggregate_mean`` /
  ``aggregate_optimality_gap``, gamma 1: the expert) with 95% stratified bootstrap intervals
  (runs resampled within each task), and performance profiles;
* for each pair, the probability of improvement P(X > Y) (a run of X beats a run of Y on the
  same task, ties half, averaged over tasks) with its stratified independent bootstrap
  interval, and a verdict (:func:`verdict`): ``better`` (X) when the interval lies above 0.5,
  ``worse`` when below, ``equivalent`` when it lies inside ``[0.40, 0.60]``
  (:data:`EQUIVALENCE`: neither is ahead by more than a tenth of the chance), else
  ``undecided`` (more seeds would tell).

Where a method has more runs on some tasks than on others (a track whose costly tasks test
on fewer seeds), every run is kept and every task weighs the same
(:mod:`abco_train.report.balanced`: the same statistics, each run weighted by one over its
task's runs, intervals by scipy's bootstrap of each task's runs on their own); no run is
dropped to make a matrix rectangular.

Scores below a random policy's (below 0) enter every aggregate and every pair at 0
(:data:`SCORE_FLOOR`): no imitation is no imitation, however far below random the returns
fall. Of the built-in tasks only LunarLander's returns have no lower bound (its shaping and
crash penalties), so without the floor one task's failure mode would set the means, their
intervals and the optimality gaps of the methods that fail there. The task tables keep the
scores as they are, and the aggregates say how many runs the floor lifted.

Example:
    >>> verdict(0.62, 0.81), verdict(0.2, 0.45), verdict(0.45, 0.58), verdict(0.35, 0.66)
    ('better', 'worse', 'equivalent', 'undecided')
    >>> ahead = standings({("abco", "bco"): (0.75, 0.6, 0.9), ("abco", "iupe"): (0.5, 0.3, 0.7)})
    >>> ahead["abco"], ahead["bco"]
    (([('bco', 0.75)], [], [], [('iupe', 0.5)]), ([], [('abco', 0.25)], [], []))
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from abco_train.report import aggregates, balanced
from abco_train.report.headline import IFO_METHODS
from abco_train.report.headline_plots import AGGREGATES_PNG, Interval, plot_aggregates

__all__ = ["EVEN", "EQUIVALENCE", "VERDICTS", "PROFILE_PNG", "SCORE_FLOOR", "Interval",
           "verdict", "standings", "Ranking", "compute", "section"]  # fmt: skip

#: P(X > Y) of two methods the benchmark cannot tell apart.
EVEN = 0.5
#: A pair whose P(X > Y) interval lies inside this band is ``equivalent``.
EQUIVALENCE = (0.40, 0.60)
#: The verdicts of a pair, from X's side.
VERDICTS = ("better", "worse", "equivalent", "undecided")
PROFILE_PNG = "headline_profile.png"
#: Scores below it count as it in the aggregates and pairs (the module docstring says why).
SCORE_FLOOR = 0.0

Scores = Mapping[str, Mapping[str, Mapping[int, float]]]  # method -> task -> seed -> score


def verdict(low: float, high: float, even: float = EVEN,
            band: tuple[float, float] = EQUIVALENCE) -> str:  # fmt: skip
    """The verdict on X of the interval ``[low, high]`` of P(X > Y): ``better`` (it excludes
    ``even`` from above), ``worse`` (from below), ``equivalent`` (inside ``band``) or
    ``undecided`` (it reaches ``even`` and leaves the band: more runs would tell)."""
    if low > even:
        return "better"
    if high < even:
        return "worse"
    return "equivalent" if band[0] <= low and high <= band[1] else "undecided"


def standings(pairs: Mapping[tuple[str, str], Interval]
              ) -> dict[str, tuple[list[tuple[str, float]], ...]]:  # fmt: skip
    """Per method: the methods it is ahead of, behind, equivalent to and undecided against,
    each with its P(method > other), from the pairs' ``P(X > Y)`` intervals (in the pairs'
    order)."""
    out: dict[str, tuple[list[tuple[str, float]], ...]] = {}
    flip = {"better": "worse", "worse": "better", "equivalent": "equivalent",
            "undecided": "undecided"}  # fmt: skip
    for (x, y), (p, low, high) in pairs.items():
        for m in (x, y):
            out.setdefault(m, ([], [], [], []))
        judged = verdict(low, high)
        out[x][VERDICTS.index(judged)].append((y, p))
        out[y][VERDICTS.index(flip[judged])].append((x, 1.0 - p))
    return out


@dataclass
class Ranking:
    """The benchmark track's aggregates: ``(point, low, high)`` per method or pair."""

    matrices: dict[str, np.ndarray]
    dropped: dict[str, int]
    left_out: dict[str, list[str]]
    iqm: dict[str, Interval] = field(default_factory=dict)
    gap: dict[str, Interval] = field(default_factory=dict)
    mean: dict[str, Interval] = field(default_factory=dict)
    profiles: dict[str, np.ndarray] = field(default_factory=dict)
    profile_cis: dict[str, np.ndarray] = field(default_factory=dict)
    taus: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pairs: dict[tuple[str, str], Interval] = field(default_factory=dict)
    floored: dict[str, dict[str, int]] = field(default_factory=dict)  # method -> task -> runs
    #: Runs per task of each method aggregated (both estimators).
    runs: dict[str, list[int]] = field(default_factory=dict)
    #: Whether the runs per task differed, so that every task was weighed the same
    #: (:mod:`abco_train.report.balanced`).
    balanced: bool = False


def compute(scores: Scores, tasks: Sequence[str], rl: SimpleNamespace, reps: int | None = None
            ) -> Ranking:  # fmt: skip
    """IQM, optimality gap, mean, performance profiles and the pairs' P(X > Y) of the IfO
    methods in ``scores`` (others are ignored), scores below :data:`SCORE_FLOOR` lifted to it,
    each bootstrap seeded (numpy seed 0)."""
    reps = int(reps or aggregates.REPS)
    ifo = {m: scores[m] for m in IFO_METHODS if m in scores}
    if any(len({len(by_task.get(t, {})) for t in tasks}) > 1 and all(map(by_task.get, tasks))
           for by_task in ifo.values()):  # fmt: skip
        return _balanced(ifo, tasks, reps)
    matrices, dropped, left_out = aggregates.score_matrices(ifo, tasks)
    floored = {m: {t: int(n) for t, n in zip(tasks, (x < SCORE_FLOOR).sum(0)) if n}
               for m, x in matrices.items()}  # fmt: skip
    matrices = {m: np.maximum(x, SCORE_FLOOR) for m, x in matrices.items()}
    out = Ranking(matrices, dropped, left_out, floored={m: f for m, f in floored.items() if f},
                  runs={m: [x.shape[0]] * len(tasks) for m, x in matrices.items()})
    if not matrices:
        return out
    metrics = rl.metrics
    with aggregates.seeded(aggregates.SEED):
        point, ci = rl.library.get_interval_estimates(
            matrices, lambda x: np.array([metrics.aggregate_iqm(x),
                                          metrics.aggregate_optimality_gap(x, 1.0),
                                          metrics.aggregate_mean(x)]), reps=reps)  # fmt: skip
    for m in matrices:
        out.iqm[m], out.gap[m], out.mean[m] = (
            (float(point[m][k]), float(ci[m][0, k]), float(ci[m][1, k])) for k in range(3))
    out.taus = aggregates.profile_taus(matrices)
    with aggregates.seeded(aggregates.SEED):
        out.profiles, out.profile_cis = rl.library.create_performance_profile(
            matrices, out.taus, reps=reps)  # fmt: skip
    pairs = {f"{x} > {y}": [matrices[x], matrices[y]]
             for x, y in itertools.combinations(list(matrices), 2)}  # fmt: skip
    if pairs:
        with aggregates.seeded(aggregates.SEED):
            _, ci = rl.library.get_interval_estimates(
                pairs, lambda x, y: np.array([aggregates.probability_of_improvement(x, y)]),
                reps=reps)  # fmt: skip
        for key, (x, y) in pairs.items():
            p = float(metrics.probability_of_improvement(x, y))
            a, b = key.split(" > ")
            out.pairs[(a, b)] = (p, float(ci[key][0, 0]), float(ci[key][1, 0]))
    return out


def _balanced(ifo: Scores, tasks: Sequence[str], reps: int) -> Ranking:
    """:func:`compute` keeping every run, each task weighing the same (the module docstring)."""
    columns: dict[str, list[np.ndarray]] = {}
    left_out: dict[str, list[str]] = {}
    for m, by_task in ifo.items():
        lacking = [t for t in tasks if not by_task.get(t)]
        if lacking:
            left_out[m] = lacking
            continue
        columns[m] = [np.array([by_task[t][s] for s in sorted(by_task[t])], dtype=np.float64)
                      for t in tasks]  # fmt: skip
    floored = {m: {t: int((c < SCORE_FLOOR).sum()) for t, c in zip(tasks, cols)
                   if (c < SCORE_FLOOR).any()} for m, cols in columns.items()}  # fmt: skip
    columns = {m: [np.maximum(c, SCORE_FLOOR) for c in cols] for m, cols in columns.items()}
    out = Ranking({}, {m: 0 for m in columns}, left_out, balanced=True,
                  floored={m: f for m, f in floored.items() if f},
                  runs={m: [len(c) for c in cols] for m, cols in columns.items()})  # fmt: skip
    for m, cols in columns.items():
        def stats(*c: np.ndarray) -> np.ndarray:
            return np.array([balanced.iqm(c), balanced.optimality_gap(c), balanced.mean(c)])

        point, (low, high) = stats(*cols), balanced.interval(stats, cols, reps, aggregates.SEED)
        out.iqm[m], out.gap[m], out.mean[m] = (
            (float(point[k]), float(low[k]), float(high[k])) for k in range(3))
    out.taus = aggregates.profile_taus({m: np.concatenate(c) for m, c in columns.items()})
    for m, cols in columns.items():
        out.profiles[m] = balanced.profile(cols, out.taus)
        out.profile_cis[m] = np.stack(balanced.interval(
            lambda *c: balanced.profile(c, out.taus), cols, reps, aggregates.SEED))
    n = len(tasks)
    for x, y in itertools.combinations(list(columns), 2):
        p = balanced.probability_of_improvement(columns[x], columns[y])
        low, high = balanced.interval(
            lambda *c: np.array([balanced.probability_of_improvement(c[:n], c[n:])]),
            [*columns[x], *columns[y]], reps, aggregates.SEED)  # fmt: skip
        out.pairs[(x, y)] = (p, float(low[0]), float(high[0]))
    return out


def _fmt(x: Interval) -> str:
    return f"{x[0]:.3f} [{x[1]:.3f}, {x[2]:.3f}]"


def section(scores: Scores, tasks: Sequence[str], out: Path, labels: Mapping[str, str],
            csv_rows: list[dict[str, Any]], older: int = 0, reps: int | None = None,
            ) -> tuple[list[str], dict[str, Path]]:  # fmt: skip
    """The aggregates and the pairwise sections (Markdown lines, CSV rows appended to
    ``csv_rows``) and their plots by name (``headline_profile``: the performance profiles,
    ``headline_aggregates``: IQM and optimality gap; none when nothing was aggregated).

    Args:
        scores: ``method -> task -> seed -> score`` of the scored runs.
        tasks: The benchmark track's tasks.
        older: Finished runs without a score (older records), left out.
    """
    n = len(tasks)
    head = [f"## Aggregates over the {n} task(s): the IfO methods", ""]
    pair_head = ["## Pairwise: which IfO methods the benchmark tells apart", ""]
    lines = [f"Each IfO method ({', '.join(IFO_METHODS)}) with scored runs on every task enters"
             f" as a (runs x {n} tasks) matrix of headline scores; BC, the references and any"
             " other method do not. Intervals: 95% stratified bootstrap"
             f" ({int(reps or aggregates.REPS):,} replicates, runs resampled within each task,"
             " seed 0) by `rliable`; where a method has more runs on some tasks than on others,"
             " every run is kept and every task weighs the same (a run weighs one over its"
             " task's runs; the same statistics, intervals by `scipy.stats.bootstrap` of each"
             " task's runs on their own). A score below a random policy's"
             f" enters at {SCORE_FLOOR:g}: doing worse than random is no more imitation than"
             " random (only LunarLander's returns are unbounded below); the task tables keep"
             " it as it is.", ""]  # fmt: skip
    if older:
        lines.append(f"- left out: {older} finished run(s) without a score (older records)")
    missing = [m for m in IFO_METHODS if m not in scores]
    if missing:
        lines.append(f"- not in the benchmark track: {', '.join(missing)}")
    rl, why = aggregates.load_rliable()
    if rl is None:
        note = (f"Not computed: {why}. `{aggregates.INSTALL_HINT}` adds the IQM, optimality gap"
                " and probability of improvement with stratified bootstrap intervals.")
        return [*head, *lines, "", note, "", *pair_head, note], {}
    ranking = compute(scores, tasks, rl, reps)
    for m, lacking in ranking.left_out.items():
        lines.append(f"- left out: {m} (no scored run on {', '.join(lacking)})")
    if ranking.balanced:
        lines.append("- runs per task differ: every method's aggregates and pairs weigh each"
                     " task the same, every run kept (`scipy.stats.bootstrap`, not rliable)")
    if not ranking.runs:
        return [*head, *lines, "", "No IfO method has scored runs on every task.", "",
                *pair_head, "Nothing to compare."], {}  # fmt: skip
    for m, tasks_lifted in ranking.floored.items():
        where = ", ".join(f"{t} {k}" for t, k in tasks_lifted.items())
        lines.append(f"- entered at {SCORE_FLOOR:g}: {labels.get(m, m)}, runs below it on"
                     f" {where}")  # fmt: skip
    lines += _aggregate_table(ranking, labels, n, csv_rows)
    png = aggregates.plot_profiles(
        ranking.profiles, ranking.profile_cis, ranking.taus, rl, labels, out / PROFILE_PNG,
        "score", f"Performance profiles of the headline score over {n} task(s) (95%"
        " stratified bootstrap bands)", 1.0)  # fmt: skip
    bars = plot_aggregates(ranking.iqm, ranking.gap, rl, labels, out / AGGREGATES_PNG)
    lines += ["", f"![IQM and optimality gap with 95% intervals]({bars.name})",
              "", f"![Performance profiles: fraction of runs with score > tau]({png.name})"]
    plots = {"headline_aggregates": bars, "headline_profile": png}
    return [*head, *lines, "", *pair_head, *_pair_lines(ranking, labels, n, csv_rows)], plots


def _aggregate_table(ranking: Ranking, labels: Mapping[str, str], n: int,
                     csv_rows: list[dict[str, Any]]) -> list[str]:  # fmt: skip
    """The methods by IQM (best first): IQM, mean and optimality gap with their intervals."""
    lines = ["", "| Rank | Method | Runs per task | IQM of score [95% CI] | Mean [95% CI] |"
             " Optimality gap [95% CI] |", "|---|---|---|---|---|---|"]  # fmt: skip
    order = sorted(ranking.runs, key=lambda m: -ranking.iqm[m][0])
    for rank, m in enumerate(order, 1):
        fewest, most = min(ranking.runs[m]), max(ranking.runs[m])
        runs = str(most) if fewest == most else f"{fewest}-{most}"
        runs += f" ({ranking.dropped[m]} dropped)" if ranking.dropped[m] else ""
        lines.append(f"| {rank} | {labels.get(m, m)} | {runs} | {_fmt(ranking.iqm[m])} |"
                     f" {_fmt(ranking.mean[m])} | {_fmt(ranking.gap[m])} |")  # fmt: skip
        base = {"table": "headline-aggregate", "env": f"all {n} tasks", "method": m,
                "evaluation": "headline", "seeds": fewest, "paper": ""}  # fmt: skip
        mean, iqm, gap = ranking.mean[m], ranking.iqm[m], ranking.gap[m]
        csv_rows.append({**base, "metric": "score", "mean": mean[0], "ci_low": mean[1],
                         "ci_high": mean[2], "iqm": iqm[0], "iqm_ci_low": iqm[1],
                         "iqm_ci_high": iqm[2]})  # fmt: skip
        csv_rows.append({**base, "metric": "optimality_gap", "mean": gap[0], "ci_low": gap[1],
                         "ci_high": gap[2]})  # fmt: skip
    lines += ["", "IQM: the mean of the middle 50% of all runs' scores over all tasks; mean: of"
              " all of them (with scores split between modes, the IQM's middle half can fall"
              " between them: read both). Optimality"
              " gap: the mean of max(1 - score, 0), how far the runs fall short of the expert"
              " (lower is better)."]  # fmt: skip
    return lines


def _pair_lines(ranking: Ranking, labels: Mapping[str, str], n: int,
                csv_rows: list[dict[str, Any]]) -> list[str]:  # fmt: skip
    """The pairs' table (P(X > Y), its interval, the verdict), then one line per method."""
    if not ranking.pairs:
        return ["Only one IfO method has scored runs on every task: nothing to compare."]
    lo, hi = EQUIVALENCE
    lines = ["P(X > Y): the probability that a run of X beats a run of Y on the same task (ties"
             " count half), averaged over tasks; 0.5: no difference. Verdict: better (the 95%"
             " interval lies above 0.5: the table names the one ahead), equivalent (the interval"
             f" lies inside [{lo:.2f}, {hi:.2f}]: neither is ahead by more than that), undecided"
             " (the interval reaches 0.5 and leaves that band: more seeds would tell).", "",
             "| X | Y | P(X > Y) [95% CI] | Verdict |", "|---|---|---|---|"]  # fmt: skip
    for (x, y), p in ranking.pairs.items():
        judged = verdict(p[1], p[2])
        if judged in ("better", "worse"):
            judged = f"better: {labels.get(x, x) if judged == 'better' else labels.get(y, y)}"
        lines.append(f"| {labels.get(x, x)} | {labels.get(y, y)} | {_fmt(p)} | {judged} |")
        csv_rows.append({"table": "pairwise", "env": f"all {n} tasks", "method": x,
                         "evaluation": "headline", "metric": f"probability_of_improvement_over_{y}",
                         "seeds": min(ranking.runs[x]), "mean": p[0], "ci_low": p[1],
                         "ci_high": p[2], "paper": ""})  # fmt: skip
    lines += ["", "Per method (`name`: P(it beats the other)):", ""]
    for m, (ahead, behind, even, open_) in standings(ranking.pairs).items():
        parts = [f"{word} {', '.join(f'`{o}` {p:.2f}' for o, p in group)}"
                 for word, group in (("ahead of", ahead), ("behind", behind),
                                     ("equivalent to", even), ("undecided against", open_))
                 if group]  # fmt: skip
        lines.append(f"- {labels.get(m, m)} (`{m}`): {'; '.join(parts)}.")
    return lines
