"""Budget curves: a task's headline score at several interaction budgets, per method.

A budget-curve grid is a track whose tasks are budget variants of a benchmark task, named
``{task}@x{multiple}`` (``acrobot-ten-random-episodes@x4``): the task's settings with its
budget, and every budget-bound option (GAIfO's ``rl_steps``), multiplied. ``abco report RUNS
--budget-curves CURVES`` reads the variants from ``CURVES`` and the 1x points from the
benchmark grid ``RUNS`` itself, and draws one panel per task: mean score over seeds (95%
interval) against the budget, one line per method, with a table of the same numbers and each
cell's mean interactions spent (a method that spends less than its budget is not
budget-bound there).

Example:
    >>> variant_of("acrobot-ten-random-episodes@x16")
    ('acrobot-ten-random-episodes', 16.0)
    >>> variant_of("lunarlander") is None
    True
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from abco_train.bench.records import escape
from abco_train.harness.plots import pyplot, save_figure
from abco_train.report.budget_verdicts import verdict_lines
from abco_train.report.headline import Cell, split_tracks, task_cells
from abco_train.report.runs import ReportError, Run, load_runs, method_order
from abco_train.report.tables import count_text, fmt, stat_row

__all__ = ["BUDGET_CURVES_PNG", "variant_of", "curves", "section"]

BUDGET_CURVES_PNG = "budget_curves.png"

#: ``task -> method -> [(budget, cell)]`` by increasing budget.
Curves = dict[str, dict[str, list[tuple[int, Cell]]]]


def variant_of(task: str) -> tuple[str, float] | None:
    """``(task, multiple)`` of a variant's name ``{task}@x{multiple}``, else ``None``."""
    base, sep, multiple = task.rpartition("@x")
    try:
        return (base, float(multiple)) if sep and base and float(multiple) > 0 else None
    except ValueError:
        return None


def curves(main: Mapping[str, Sequence[Run]], curves_dir: str | Path,
           skipped: list[Any] | None = None) -> Curves:  # fmt: skip
    """The curves of the variants in ``curves_dir`` with their 1x points from ``main`` (the
    benchmark grid's runs by task, on the seeds the variants ran), for the methods that have a
    variant.

    Raises:
        ReportError: ``curves_dir`` is not a folder or holds no task named as a variant, or
            a variant's records carry another budget than its multiple of its task's.
    """
    if not Path(curves_dir).is_dir():
        raise ReportError(f"--budget-curves {escape(curves_dir, 200)} is not a folder")
    by_task, _ = split_tracks(load_runs(curves_dir, skipped))
    variants = {t: v for t in by_task if (v := variant_of(t)) is not None}
    if not variants:
        raise ReportError(f"--budget-curves {escape(curves_dir, 200)} holds no task named "
                          "TASK@xMULTIPLE (a budget variant of a benchmark task)")  # fmt: skip
    seeds: dict[str, set[int]] = {}  # base task -> the seeds its variants ran
    for task, (base, _) in variants.items():
        seeds.setdefault(base, set()).update(r.seed for r in by_task[task])
    ones = task_cells({b: [r for r in main.get(b, ()) if r.seed in seeds[b]] for b in seeds})
    out: Curves = {}
    for task, by_method in task_cells({t: by_task[t] for t in variants}).items():
        base, multiple = variants[task]
        for method, cell in by_method.items():
            points = out.setdefault(base, {}).setdefault(method, [])
            one = ones.get(base, {}).get(method)
            if one is not None and one.budgets and cell.budgets:
                _check_budget(task, cell, multiple * min(one.budgets))
            if cell.budgets:  # none: no finished record to place it
                points.append((min(cell.budgets), cell))
    for base, by_method in out.items():
        for method, points in by_method.items():
            one = ones.get(base, {}).get(method)
            if one is not None and one.budgets:
                points.append((min(one.budgets), one))
            points.sort(key=lambda p: p[0])
    return out


def _check_budget(task: str, cell: Cell, expected: float) -> None:
    """Refuse a variant whose records carry another budget than its multiple of its task's."""
    if cell.budgets != {round(expected)}:
        found = ", ".join(f"{b:,}" for b in sorted(cell.budgets))
        raise ReportError(f"budget variant {escape(task, 120)}: {cell.method}'s records carry "
                          f"budget {found}, not {round(expected):,} (its multiple of the "
                          "task's budget)")  # fmt: skip


def section(data: Curves, out: Path, labels: Mapping[str, str],
            csv_rows: list[dict[str, Any]]) -> tuple[list[str], Path | None]:  # fmt: skip
    """The budget curves' Markdown lines (CSV rows appended) and their plot in ``out``."""
    lines = ["## Budget curves", "",
             "Each task's headline score at several interaction budgets: the 1x point is the "
             "benchmark grid's runs on the seeds the variants ran, the others run the task "
             "with its budget (and GAIfO's PPO steps) multiplied, nothing else changed. Score: "
             "mean over seeds [95% bootstrap interval]; spent: mean interactions per finished "
             "run.", ""]  # fmt: skip
    for base, by_method in data.items():
        budgets = sorted({b for points in by_method.values() for b, _ in points})
        lines += [f"### {escape(base)}", "",
                  "| Method | " + " | ".join(f"{b:,}" for b in budgets) + " |",
                  "|---|" + "---|" * len(budgets)]  # fmt: skip
        for method in method_order(by_method):
            found = dict(by_method[method])
            row = [_point(found.get(b)) for b in budgets]
            lines.append(f"| {escape(labels.get(method, method), 80)} | {' | '.join(row)} |")
            for budget, cell in by_method[method]:
                if cell.stats is not None:
                    csv_rows.append(stat_row("budget_curve", base, method, f"budget {budget}",
                                             "score", cell.stats))  # fmt: skip
        lines.append("")
    lines += [*verdict_lines(data, labels), ""]
    return lines, _plot(data, out / BUDGET_CURVES_PNG, labels)


def _point(cell: Cell | None) -> str:
    if cell is None or cell.stats is None:
        return "–"
    s = cell.stats
    spent = count_text(float(np.mean(cell.spent))) if cell.spent else "–"
    stopped = f", {cell.stopped} stopped" if cell.stopped else ""
    return f"{fmt(s.mean)} [{fmt(s.ci[0])}, {fmt(s.ci[1])}] (n={s.n}{stopped}; spent {spent})"


def _plot(data: Curves, path: Path, labels: Mapping[str, str]) -> Path | None:
    panels = [b for b, by_method in data.items() if any(len(p) for p in by_method.values())]
    if not panels:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.4), squeeze=False)
    for ax, base in zip(axes.flat, panels):
        methods = method_order(data[base])
        budgets: set[float] = set()
        for i, method in enumerate(methods):
            points = [(b, c.stats) for b, c in data[base][method] if c.stats is not None]
            if not points:
                continue
            budgets.update(b for b, _ in points)
            # methods side by side at each budget (a few percent apart on the log axis), so
            # that their intervals do not hide each other
            dodge = 1.04 ** (i - (len(methods) - 1) / 2)
            x = np.array([b * dodge for b, _ in points], dtype=float)
            mean = np.array([s.mean for _, s in points])
            err = np.array([[s.mean - s.ci[0] for _, s in points],
                            [s.ci[1] - s.mean for _, s in points]])  # fmt: skip
            ax.errorbar(x, mean, yerr=err, marker="o", capsize=3, label=labels.get(method, method))
        ax.set_xscale("log")
        ticks = sorted(budgets)  # one labelled tick per budget run, no log-scale minor labels
        ax.set_xticks(ticks, [f"{t:,.0f}" for t in ticks], fontsize=8)
        ax.minorticks_off()
        ax.set_title(base, fontsize=9)
        ax.set_xlabel("interaction budget")
        ax.set_ylabel("score (0 random, 1 expert)")
        ax.axhline(0.0, color="grey", lw=0.5)
        ax.axhline(1.0, color="grey", lw=0.5, ls="--")
        ax.legend(fontsize=7)
    return save_figure(fig, path)
