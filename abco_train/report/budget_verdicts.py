"""Whether a pair's verdict hangs on the budget: the pairwise comparison of the IfO methods at
each point of the budget curves.

At every budget multiple (1x: the benchmark grid's runs; 4x, 16x: the variants), the IfO
methods' runs on the tasks with curves are compared as the benchmark track's pairs are
(:func:`abco_train.report.ranking.compute`: the probability of improvement with its 95%
stratified bootstrap interval, and its :func:`~abco_train.report.ranking.verdict`). A pair
*holds* when its verdict is the same at every budget.

Example:
    >>> holds({1.0: "better", 4.0: "better"}, [1.0, 4.0]), holds({1.0: "better"}, [1.0, 4.0])
    ('yes', 'not at every budget')
    >>> holds({1.0: "better", 16.0: "equivalent"}, [1.0, 16.0])
    'no'
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from abco_train.bench.records import escape
from abco_train.report import aggregates
from abco_train.report.headline import Cell
from abco_train.report.ranking import compute, verdict

__all__ = ["verdicts_by_budget", "holds", "verdict_lines"]

#: ``task -> method -> [(budget, cell)]`` (:data:`abco_train.report.budget_curves.Curves`).
CurvePoints = Mapping[str, Mapping[str, Sequence[tuple[int, Cell]]]]


def verdicts_by_budget(data: CurvePoints, rl: Any, reps: int | None = None
                       ) -> dict[tuple[str, str], dict[float, str]]:  # fmt: skip
    """``(X, Y) -> multiple -> verdict on X`` at each budget multiple of the curves."""
    by_multiple: dict[float, dict[str, dict[str, dict[int, float]]]] = {}
    for task, by_method in data.items():
        base = min(b for points in by_method.values() for b, _ in points)
        for method, points in by_method.items():
            for budget, cell in points:
                if cell.scored and cell.values:
                    by_multiple.setdefault(budget / base, {}).setdefault(method, {})[task] = (
                        dict(cell.values))
    out: dict[tuple[str, str], dict[float, str]] = {}
    for multiple, scores in sorted(by_multiple.items()):
        tasks = sorted({t for per_task in scores.values() for t in per_task})
        for pair, (_, low, high) in compute(scores, tasks, rl, reps).pairs.items():
            out.setdefault(pair, {})[multiple] = verdict(low, high)
    return out


def holds(verdicts: Mapping[float, str], multiples: Sequence[float]) -> str:
    """``yes`` (one verdict at every budget), ``no``, or ``not at every budget`` (missing)."""
    if any(m not in verdicts for m in multiples):
        return "not at every budget"
    return "yes" if len(set(verdicts.values())) == 1 else "no"


def verdict_lines(data: CurvePoints, labels: Mapping[str, str], reps: int | None = None
                  ) -> list[str]:  # fmt: skip
    """The "Verdicts across budgets" lines of the budget curves."""
    head = ["### Verdicts across budgets", ""]
    rl, why = aggregates.load_rliable()
    if rl is None:
        return [*head, f"Not computed: {why}."]
    found = verdicts_by_budget(data, rl, reps)
    if not found:
        return [*head, "No pair of IfO methods has scored runs at any budget."]
    multiples = sorted({m for per in found.values() for m in per})
    lines = [*head, "Per pair of IfO methods, the verdict on the first at each budget "
             "multiple, over the tasks with curves (the probability of improvement's 95% "
             "interval: better, worse, equivalent inside [0.40, 0.60], undecided); *holds*: "
             "the same verdict at every budget.", "",
             "| Pair | " + " | ".join(f"{m:g}x" for m in multiples) + " | Holds |",
             "|---|" + "---|" * len(multiples) + "---|"]  # fmt: skip
    for (x, y), per in found.items():
        name = f"{escape(labels.get(x, x), 60)} vs {escape(labels.get(y, y), 60)}"
        cells = " | ".join(per.get(m, "–") for m in multiples)
        lines.append(f"| {name} | {cells} | {holds(per, multiples)} |")
    kept = sum(holds(per, multiples) == "yes" for per in found.values())
    return [*lines, "", f"{kept} of {len(found)} pair(s) keep their verdict at every budget."]
