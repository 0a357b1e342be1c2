"""The headline of ``abco report``: the benchmark track's tasks, each method ranked by its score.

Records that carry a ``task`` (runs under ``OUT/{task}/{method}/seed{n}``) form the benchmark
track. A run is ranked by its headline evaluation (``final.json`` ``headline``: the key of one
of its evaluation blocks; a record without one: ``train/paper`` on a maze, ``episodes``
elsewhere) and that block's ``score``: the mean over episodes of (R - R_random) / (R_expert -
R_random), both references measured under the same protocol on the same layouts with seeds of
their own (0: the random policy, 1: the expert). An older record without a score shows the
paper's P of the block instead, marked as such, and stays out of the aggregates.

Each task gets one table (:func:`task_table`): the IfO methods and any other method ranked by
their mean score over seeds, then ``bc`` (true actions: a labelled reference, never in the IfO
aggregates) and the reference rows ``expert`` and ``random``, present in every table.

Example:
    >>> block = {"performance": 0.7, "aer": 1.0, "score": 0.9}
    >>> headline_value({"env": "CartPole-v1", "episodes": block})
    (0.9, True)
    >>> headline_value({"env": "AbcoMaze5x5-v0", "headline": "test/paper",
    ...                 "test/paper": {"performance": 0.7, "aer": 1.0}})
    (0.7, False)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from abco_train.bench.records import RecordError, check_config, check_name, escape, read_json
from abco_train.config.fields import ConfigError
from abco_train.harness.run_folder import CONFIG
from abco_train.report.runs import LABELS, Run, method_order, table_evaluation
from abco_train.report.stats import CellStats, cell_stats
from abco_train.report.tables import count_text, fmt, stat_row

__all__ = ["IFO_METHODS", "TRUE_ACTION_METHODS", "REFERENCE_METHODS", "HEADLINE_LABELS",
           "NOTES", "OLDER", "headline_key", "headline_value", "split_tracks", "Cell",
           "task_cells", "role", "overview_table", "task_table", "intro"]  # fmt: skip

#: The IfO methods of the benchmark: the aggregates and the pairwise comparisons are theirs.
IFO_METHODS = ("bco", "bco-alpha", "bco-alpha-torabi", "abco", "iupe", "ilpo", "gaifo", "dilo",
               "lapo")
#: Methods that train on the expert's true actions: labelled references, outside the aggregates.
TRUE_ACTION_METHODS = ("bc",)
#: The ends of the score's scale, run through the same evaluation: a row in every task's table.
REFERENCE_METHODS = ("expert", "random")
HEADLINE_LABELS = {**LABELS, "ilpo": "ILPO (abco's variant)", "expert": "Expert",
                   "random": "Random"}  # fmt: skip
#: What a row is, where the label alone could mislead.
NOTES = {
    "bc": "true actions: a reference, outside the IfO aggregates",
    "ilpo": "abco's variant of ILPO: its design departs from the paper's (abco_train.methods.ilpo)",
    "expert": "reference: the dataset's expert (the scale's 1, measured on seeds of its own)",
    "random": "reference: uniform random actions (the scale's 0, measured on seeds of its own)",
}  # fmt: skip
#: The note of a cell shown with the paper's P: its records predate the score.
OLDER = "no score: older record (the paper's P)"


def headline_key(final: Mapping[str, Any]) -> str:
    """The evaluation a record is ranked by: its ``headline``, else ``train/paper`` on a maze
    and ``episodes`` elsewhere (an env abco does not know: ``episodes``)."""
    if isinstance(final.get("headline"), str):
        return final["headline"]
    try:
        return table_evaluation(str(final.get("env")))
    except ConfigError:
        return "episodes"


def headline_value(final: Mapping[str, Any]) -> tuple[float, bool] | None:
    """``(score, True)`` of the record's headline evaluation, ``(P, False)`` for an older
    record without a score, ``None`` without that evaluation."""
    block = final.get(headline_key(final))
    if not isinstance(block, dict) or "performance" not in block:
        return None
    if block.get("score") is not None:
        return float(block["score"]), True
    return float(block["performance"]), False


def _config_task(run: Run) -> str | None:
    """The ``task`` of a run folder's ``config.json`` (``None``: none, or unreadable)."""
    try:
        task = check_config(read_json(run.path / CONFIG)).get("task")
        return None if task is None else check_name(task, "task")
    except (FileNotFoundError, RecordError):
        return None


def split_tracks(runs: Iterable[Run]) -> tuple[dict[str, list[Run]], list[Run]]:
    """The benchmark track's runs by task, and the paper track's runs (records without a task).

    A run without a record of its own (unfinished, or its ``final.json`` skipped) belongs to a
    task when its folder is named after one of the grid's tasks, or its ``config.json`` names
    one.
    """
    runs = list(runs)
    tasks = {str(r.final["task"]) for r in runs if r.final and r.final.get("task") is not None}
    by_task: dict[str, list[Run]] = {}
    paper: list[Run] = []
    for r in runs:
        task = (r.final or {}).get("task")
        if task is None and r.final is None:
            task = r.env if r.env in tasks else _config_task(r)
        if task is None:
            paper.append(r)
        else:
            by_task.setdefault(str(task), []).append(r)
    return dict(sorted(by_task.items())), paper


@dataclass
class Cell:
    """One (task, method) of the benchmark track: its runs' headline numbers."""

    task: str
    method: str
    #: Seed -> headline value of the finished runs (their scores; the paper's P when none of
    #: them has a score).
    values: dict[int, float] = field(default_factory=dict)
    scored: bool = True
    evaluations: set[str] = field(default_factory=set)
    #: Finished runs without a score beside runs with one (left out), runs a method stopped.
    older: int = 0
    stopped: int = 0
    success: list[float] = field(default_factory=list)
    spent: list[int] = field(default_factory=list)
    budgets: set[int] = field(default_factory=set)
    stats: CellStats | None = None

    @property
    def mean(self) -> float:
        return self.stats.mean if self.stats else float("-inf")


def _cell(task: str, method: str, runs: Sequence[Run]) -> Cell:
    cell = Cell(task, method)
    values: dict[bool, dict[int, float]] = {True: {}, False: {}}
    for r in runs:
        final = r.final or {}
        if isinstance(final.get("budget"), int):
            cell.budgets.add(final["budget"])
        if r.status != "ok":
            if r.status not in ("unfinished", "damaged"):
                cell.stopped += 1  # no policy came out: it counts as the random one (score 0)
                values[True][r.seed] = 0.0
            continue
        found = headline_value(final)
        if found is None:
            continue
        values[found[1]][r.seed] = found[0]
        cell.evaluations.add(headline_key(final))
        block = final[headline_key(final)]
        if block.get("success_rate") is not None:
            cell.success.append(float(block["success_rate"]))
        counts = final.get("interactions")
        if isinstance(counts, dict):
            cell.spent.append(int(sum(counts.values())))
    cell.scored = bool(values[True]) or not values[False]
    cell.values = values[cell.scored]
    cell.older = len(values[False]) if cell.scored else 0
    # seeds only: a run's score is one number, its episodes are not resampled
    cell.stats = cell_stats([np.array([v]) for _, v in sorted(cell.values.items())])
    return cell


def task_cells(by_task: Mapping[str, Sequence[Run]]) -> dict[str, dict[str, Cell]]:
    """``task -> method -> Cell`` of every method with a run on the task."""
    out: dict[str, dict[str, Cell]] = {}
    for task, runs in by_task.items():
        methods = method_order({r.method for r in runs})
        out[task] = {m: _cell(task, m, [r for r in runs if r.method == m]) for m in methods}
    return out


def role(method: str) -> str:
    """A method's role in the tables: ``reference``, ``true actions``, ``IfO`` or ``other``."""
    if method in REFERENCE_METHODS:
        return "reference"
    if method in TRUE_ACTION_METHODS:
        return "true actions"
    return "IfO" if method in IFO_METHODS else "other"


def _spent_text(cell: Cell) -> str:
    """Mean interactions per finished run against the budget: ``1,200 / 5,000 (24%)``."""
    spent = float(np.mean(cell.spent)) if cell.spent else None
    if not cell.budgets:
        return f"{count_text(spent)} / –"
    low, high = min(cell.budgets), max(cell.budgets)
    if low != high:  # runs given different budgets: no one share to show
        return f"{count_text(spent)} / {low:,}-{high:,}"
    return f"{count_text(spent)} / {low:,}" + (f" ({spent / low:.0%})" if spent is not None else "")


def _notes(cell: Cell, flagged: Mapping[str, int]) -> str:
    notes = [NOTES[cell.method]] if cell.method in NOTES else []
    if not cell.scored:
        notes.append(OLDER)
    if cell.older:
        notes.append(f"{cell.older} older record(s) without a score left out")
    if len(cell.evaluations) > 1:
        notes.append("headline evaluations differ: " + ", ".join(sorted(cell.evaluations)))
    if cell.stopped:
        notes.append(f"{cell.stopped} run(s) stopped by their method (no result): scored 0, "
                     "the random policy's")
    elif cell.stats is None:
        notes.append("no finished run")
    for state, text in (("other", "made by another code version"),
                        ("none", "without a code version")):  # fmt: skip
        if flagged.get(state):
            notes.append(f"{flagged[state]} record(s) {text} (see Code versions)")
    return escape("; ".join(notes), 600) or "–"


def _row_order(cells: Mapping[str, Cell]) -> list[tuple[str, str]]:
    """``(rank, method)``: the IfO and other methods by mean score (best first; a method with
    no result last, unranked), then the true-action methods and the references."""
    order = {m: i for i, m in enumerate(method_order(cells))}
    ranked = sorted((m for m in cells if role(m) in ("IfO", "other")),
                    key=lambda m: (-cells[m].mean, order[m]))  # fmt: skip
    rows = [(str(i + 1) if cells[m].stats else "–", m) for i, m in enumerate(ranked)]
    rows += [("–", m) for m in cells if role(m) == "true actions"]
    return rows + [("–", m) for m in REFERENCE_METHODS]


def overview_table(cells: Mapping[str, Mapping[str, Cell]]) -> list[str]:
    """Every method's mean score on every task, one row per method: the task tables at a
    glance (their order of methods; ``(P)``: an older record's P, ``–``: not run)."""
    methods = method_order({m for by_method in cells.values() for m in by_method})
    rows = [m for m in methods if role(m) in ("IfO", "other")]
    rows += [m for m in methods if role(m) == "true actions"]
    rows += [m for m in REFERENCE_METHODS if m in methods]
    lines = ["| Method | Role | " + " | ".join(escape(t, 80) for t in cells) + " |",
             "|---|---|" + "---:|" * len(cells)]  # fmt: skip
    for method in rows:
        values = []
        for by_method in cells.values():
            cell = by_method.get(method)
            s = cell.stats if cell is not None else None
            values.append("–" if cell is None or s is None else
                          fmt(s.mean) + ("" if cell.scored else " (P)"))  # fmt: skip
        label = escape(HEADLINE_LABELS.get(method, method), 80)
        lines.append(f"| {label} | {role(method)} | " + " | ".join(values) + " |")
    return lines


def task_table(task: str, cells: Mapping[str, Cell], flagged: Mapping[str, Mapping[str, int]],
               csv_rows: list[dict[str, Any]]) -> list[str]:  # fmt: skip
    """One task's table (its CSV rows appended); ``flagged``: per method, its records by code
    version state (``other``: made by another version, ``none``: without one; see
    :func:`abco_train.report.provenance.version_state`)."""
    evaluations = sorted({e for c in cells.values() for e in c.evaluations})
    shown = escape(", ".join(evaluations) or "–")
    lines = [f"### {escape(task)}", "", f"Headline evaluation: {shown}.",
             "", "| Rank | Method | Role | Seeds | Score mean [95% CI] | Success |"
             " Interactions / budget | Note |", "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for rank, method in _row_order(cells):
        label = escape(HEADLINE_LABELS.get(method, method), 80)
        cell = cells.get(method)
        if cell is None:
            lines.append(f"| – | {label} | {role(method)} | 0 | not run | – | – |"
                         f" {NOTES.get(method, '–')} |")  # fmt: skip
            continue
        s = cell.stats
        seeds = str(s.n if s else 0) + (f" ({cell.stopped} stopped)" if cell.stopped else "")
        score = "–" if s is None else f"{fmt(s.mean)} [{fmt(s.ci[0])}, {fmt(s.ci[1])}]"
        score += "" if cell.scored or s is None else " (P)"
        success = fmt(float(np.mean(cell.success)), 2) if cell.success else "–"
        lines.append(f"| {rank} | {label} | {role(method)} | {seeds} | {score} | {success} |"
                     f" {_spent_text(cell)} | {_notes(cell, flagged.get(method, {}))} |")
        _csv(task, cell, csv_rows)
    not_run = [m for m in IFO_METHODS if m not in cells]
    if not_run:
        lines += ["", f"Not run on this task: {', '.join(not_run)}."]
    return lines


def _csv(task: str, cell: Cell, csv_rows: list[dict[str, Any]]) -> None:
    """The cell's CSV rows: its score (or P), success rate, interactions and budget."""
    evaluation = ", ".join(sorted(cell.evaluations))
    if cell.stats is not None:
        csv_rows.append(stat_row("headline", task, cell.method, evaluation,
                                 "score" if cell.scored else "performance", cell.stats))
    per_run = {"success_rate": cell.success, "interactions/total": cell.spent}
    for metric, values in per_run.items():
        s = cell_stats([np.array([float(v)]) for v in values])
        if s is not None:
            csv_rows.append(stat_row("headline", task, cell.method,
                                     evaluation if metric == "success_rate" else "training",
                                     metric, s))  # fmt: skip
    if cell.budgets:
        csv_rows.append({**stat_row("headline", task, cell.method, "training", "budget", None),
                         "seeds": "", "mean": min(cell.budgets)})  # fmt: skip


def intro(n_tasks: int, n_runs: int, settings: str) -> list[str]:
    """The paragraph above the task tables."""
    return [
        f"{n_runs} run(s) on {n_tasks} task(s) of the benchmark track (records that carry a"
        " task). Each run is ranked by its headline evaluation's score: the mean over episodes"
        " of (R - R_random) / (R_expert - R_random), both references measured under the same"
        " protocol on the same layouts with seeds of their own (0: random actions, 1: the"
        " expert).", "",
        "Score: mean over seeds with a 95% percentile bootstrap interval over seeds (each run"
        " one number; 10,000 replicates, numpy, seed 0; with few seeds the interval is"
        " narrow: it undercovers). Success: mean success rate over seeds. Interactions: mean"
        " environment interactions per finished run, all kinds summed, against the task's"
        " budget (evaluation episodes are not counted). Rank: the IfO methods (and any method of"
        " your own) by mean score; BC trains on true actions and is shown as a reference only;"
        " Expert and Random are the scale's references.",
        "", f"Settings: {settings}.",
    ]  # fmt: skip
