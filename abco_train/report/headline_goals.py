"""The benchmark track's goals, checked from its records: each met or missed, with its figures.

* **References**: ``random`` within ±0.05 of 0 and ``expert`` within ±0.05 of 1 on every task.
* **Headroom**: on at least 5 of 7 tasks (the same share of any other number) the best IfO
  method's mean score is at most 0.90, and on every task some IfO method scores above 0.10.
* **Precision**: every IfO method's aggregate IQM has a 95% interval narrower than 0.10; and
  its mean score a 95% interval at most 0.10 wide (the goal of the track's second grid,
  whose aggregates lead with the mean beside the IQM).
* **Budget**: no run spent more than its task's budget or stopped ``over_budget``.
* **Wall time**: the grid within 4 hours (``bench_log.jsonl``:
  :func:`abco_train.report.tables.wall`); while the grid's last session stopped before its
  end the time so far is "not yet" a verdict, unless it is already over.

Example:
    >>> line = reference_line("random", {"cartpole": 0.01, "acrobot": -0.07}, 0.0)
    >>> line.startswith("- missed: Random within ±0.05 of 0"), line.endswith("(outside: acrobot)")
    (True, True)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from abco_train.bench.records import escape
from abco_train.report.headline import HEADLINE_LABELS, IFO_METHODS, Cell
from abco_train.report.runs import Run
from abco_train.report.tables import fmt

__all__ = ["HEADLINE_GOALS", "goals_section", "reference_line"]

#: The goals' thresholds.
HEADLINE_GOALS = {"reference_tolerance": 0.05, "headroom_max": 0.90, "headroom_share": 5 / 7,
                  "learnable_min": 0.10, "iqm_ci_width": 0.10, "mean_ci_width": 0.10,
                  "wall_s": 4 * 3600.0}  # fmt: skip


def _label(method: str) -> str:
    return str(HEADLINE_LABELS.get(method) or method)


def _verdict(met: bool) -> str:
    return "met" if met else "missed"


def reference_line(method: str, means: Mapping[str, float], target: float,
                   tasks: Sequence[str] = ()) -> str:  # fmt: skip
    """The line of one reference method: its mean score per task against ``target`` (a task
    of ``tasks`` it did not run on misses the goal)."""
    tol = HEADLINE_GOALS["reference_tolerance"]
    outside = [t for t, m in means.items() if abs(m - target) > tol + 1e-9]  # 1 - 0.95 > 0.05
    absent = [t for t in tasks if t not in means]
    figures = ", ".join(f"{escape(t, 80)} {fmt(m)}" for t, m in means.items())
    where = (f" (outside: {', '.join(outside)})" if outside else "") + (
        f" (not run: {', '.join(absent)})" if absent else "")
    label = HEADLINE_LABELS.get(method, method)
    met = not outside and not absent and bool(means)
    return (f"- {_verdict(met)}: {label} within ±{tol:.2f} of {target:g} on every task: "
            f"{figures or 'not run'}{where}")


def _headroom(cells: Mapping[str, Mapping[str, Cell]]) -> list[str]:
    best: dict[str, tuple[str, float]] = {}
    for task, by_method in cells.items():
        ifo = [(m, c.mean) for m, c in by_method.items() if m in IFO_METHODS and c.stats]
        if ifo:
            best[task] = max(ifo, key=lambda p: p[1])
    cap, floor = HEADLINE_GOALS["headroom_max"], HEADLINE_GOALS["learnable_min"]
    below = [t for t, (_, s) in best.items() if s <= cap]
    need = math.ceil(HEADLINE_GOALS["headroom_share"] * len(cells) - 1e-9)  # 5/7 * 7: 5
    hopeless = [t for t in cells if t not in best or best[t][1] <= floor]
    figures = "; ".join(f"{escape(t, 80)} {_label(m)} {fmt(s)}"
                        for t, (m, s) in best.items())  # fmt: skip
    return [f"- {_verdict(len(below) >= need)}: headroom, the best IfO method at most {cap:.2f} "
            f"on at least {need} of {len(cells)} tasks: {len(below)} ({figures})",
            f"- {_verdict(not hopeless)}: learnable, some IfO method above {floor:.2f} on every "
            f"task" + (f"; not on {', '.join(hopeless)}" if hopeless else "")]  # fmt: skip


def _precision(csv_rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The IQM's line (its interval narrower than the goal) and the mean's (at most it)."""
    rows = {r["method"]: r for r in csv_rows
            if r.get("table") == "headline-aggregate" and r.get("metric") == "score"}  # fmt: skip
    if not rows:
        return ["- not checked: precision (no IQM computed: rliable missing, or no IfO method "
                "with scored runs on every task; see Aggregates)"]
    missing = [m for m in IFO_METHODS if m not in rows]
    absent = f". No aggregate: {'; '.join(_label(m) for m in missing)}" if missing else ""
    lines = []
    # the IQM's goal is strict (narrower than), the mean's inclusive (at most)
    for what, low, high, goal, strict in (
            ("IQM", "iqm_ci_low", "iqm_ci_high", "iqm_ci_width", True),
            ("mean score", "ci_low", "ci_high", "mean_ci_width", False)):  # fmt: skip
        width = HEADLINE_GOALS[goal]
        widths = {m: float(r[high]) - float(r[low]) for m, r in rows.items()}
        wide = [m for m, w in widths.items() if w > width or (strict and w == width)]
        bound = f"narrower than {width:.2f}" if strict else f"at most {width:.2f} wide"
        figures = "; ".join(f"{_label(m)} {w:.3f}" for m, w in widths.items())
        lines.append(f"- {_verdict(not wide and not missing)}: precision, every IfO method's "
                     f"{what} 95% interval {bound}: widths {figures}"
                     + (f". Too wide: {'; '.join(_label(m) for m in wide)}" if wide else "")
                     + absent)  # fmt: skip
    return lines


def _budget(runs: Sequence[Run]) -> str:
    over = []
    for r in runs:
        final = r.final or {}
        counts, budget = final.get("interactions"), final.get("budget")
        spent = sum(counts.values()) if isinstance(counts, dict) else None
        if r.status == "over_budget" or (isinstance(budget, int) and spent is not None
                                         and spent > budget):  # fmt: skip
            over.append(r.where or f"{r.env}/{r.method}/seed{r.seed}")
    shown = ", ".join(escape(w, 120) for w in over[:10]) + (" ..." if len(over) > 10 else "")
    return (f"- {_verdict(not over)}: no run over its task's budget ({len(runs)} runs"
            + (f"; over: {shown})" if over else ")"))


def _wall(wall_s: float | None, unfinished: str | None) -> str:
    limit = HEADLINE_GOALS["wall_s"]
    if wall_s is None:
        return "- not checked: wall time (no bench_log.jsonl)"
    goal = f"the grid within {limit / 3600:g} h of wall time: {wall_s / 3600:.2f} h"
    if unfinished is not None:  # a partial grid's time says nothing of the whole grid's
        verdict = "missed" if wall_s > limit else "not yet"
        return f"- {verdict}: {goal} so far, the grid not finished ({escape(unfinished, 200)})"
    return f"- {_verdict(wall_s <= limit)}: {goal} (see Wall time)"


def goals_section(cells: Mapping[str, Mapping[str, Cell]], runs: Sequence[Run],
                  csv_rows: Sequence[Mapping[str, Any]], wall_s: float | None,
                  unfinished: str | None = None) -> list[str]:  # fmt: skip
    """The goals' section: one line per goal, met or missed, with its figures; ``unfinished``
    says why the grid is not finished yet (its wall time is then no verdict unless over)."""
    refs = [reference_line(m, {t: by[m].mean for t, by in cells.items()
                               if m in by and by[m].stats}, target, list(cells))
            for m, target in (("random", 0.0), ("expert", 1.0))]  # fmt: skip
    partial = ("" if unfinished is None else
               " The grid is not finished: each verdict covers the tasks and cells finished so "
               "far, and may change when the rest is in.")  # fmt: skip
    return ["## Goals of the benchmark track", "",
            "Checked from the records above (the protocol's goals); a missed goal is reported "
            f"with its figures.{partial}", "", *refs, *_headroom(cells), *_precision(csv_rows),
            _budget(runs), _wall(wall_s, unfinished)]  # fmt: skip
