"""The generalisation section of ``abco report``: runs on the first K procedural layouts, and
runs evaluated on fresh layouts, against the standard-data runs of the same methods.

Its table gives, per (env, method, K), P and the success rate on the layouts trained on, the
held-out test split and fresh layouts; its plot is
:func:`abco_train.report.plots.plot_generalisation`. The report (:mod:`abco_train.report.write`)
puts the section in.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from abco_train.report.plots import GENERALISATION_PNG, plot_generalisation
from abco_train.report.runs import LABELS, Run, env_order, method_order
from abco_train.report.stats import cell_stats
from abco_train.report.tables import ci_text, fmt, seed_text, stat_row

__all__ = ["GENERALISATION_SPLITS", "INTRO", "CAPTION", "generalisation_cells",
           "generalisation_table", "section"]  # fmt: skip

#: The evaluations of the generalisation table: the layouts trained on (a run on the first K
#: procedural layouts: 100 of them; else the pool's train split), the held-out test split,
#: and fresh layouts (in no dataset), each under the paper's protocol.
GENERALISATION_SPLITS = ("train", "test", "fresh")

#: The paragraph above the table (when the grid has such runs).
INTRO = (
    "Runs trained on the first K layouts of the procedural datasets (`--layouts K`), and",
    "beside them the same methods' runs on the standard datasets (K `standard`: the",
    "pool's 100 train layouts, 10 expert paths each). Train: the layouts trained on (the",
    "first 100 of a procedural run's; the pool's train split for a standard run); Test:",
    "the pool's 100 held-out test layouts; Fresh: 100 fresh layouts, in no dataset",
    "(`abco_envs.fresh_layouts(n, 100, 300000000)`, the same for every run). Paper",
    "protocol; P mean over seeds with its 95% bootstrap CI (seeds, then episodes); success",
    "rate: mean over seeds.", "")  # fmt: skip

#: The plot's caption in the report.
CAPTION = ("Held-out success rate and P against the number of training layouts (test"
           " split solid, fresh layouts dashed)")  # fmt: skip

Cells = dict[tuple[str, str, "int | None"], list[Run]]


def section(runs: Sequence[Run], csv_rows: list[dict[str, Any]], out: Path,
            labels: Mapping[str, str]) -> tuple[list[str], Path | None]:  # fmt: skip
    """The section's Markdown lines (its CSV rows appended to ``csv_rows``) and its plot in
    ``out`` (``None``: no run to plot)."""
    cells = generalisation_cells(runs)
    lines = [*(INTRO if cells else ()), *generalisation_table(cells, csv_rows)]
    return lines, plot_generalisation(cells, out / GENERALISATION_PNG, labels, env_order)


def generalisation_cells(runs: Sequence[Run]) -> Cells:
    """The finished maze runs of the generalisation section by (env, method, layouts).

    Every run on procedural layouts (``layouts`` K set), every run evaluated on fresh layouts,
    and, beside them, the standard-data runs of the same (env, method) (``layouts`` ``None``);
    empty when the grid has neither of the first two.
    """
    done = [r for r in runs if r.status == "ok" and r.final is not None]
    special = [r for r in done if r.layouts is not None or "fresh/paper" in (r.final or {})]
    pairs = {(r.env, r.method) for r in special}
    cells: Cells = {}
    for r in done:
        if (r.env, r.method) in pairs:
            cells.setdefault((r.env, r.method, r.layouts), []).append(r)
    order = {m: i for i, m in enumerate(method_order({m for _, m, _ in cells}))}
    return dict(sorted(cells.items(), key=lambda kv: (env_order(kv[0][0]), order[kv[0][1]],
                                                      -1 if kv[0][2] is None else kv[0][2])))


def _layouts_text(k: int | None) -> str:
    return "standard" if k is None else f"{k:,}"


def generalisation_table(cells: Cells, csv_rows: list[dict[str, Any]]) -> list[str]:
    """The generalisation table of :func:`generalisation_cells`: per env, method and number of
    training layouts, P and the success rate on the layouts trained on, the held-out test
    split and fresh layouts."""
    if not cells:
        return ["No run trained on procedural layouts (`abco bench --layouts K,...`) or was"
                " evaluated on fresh layouts (`--eval-fresh`)."]  # fmt: skip
    head = "| Env | Method | Layouts | Seeds |" + "".join(
        f" {s.capitalize()} P mean [95% CI] | {s.capitalize()} success |"
        for s in GENERALISATION_SPLITS)
    lines = [head, "|" + "---|" * head.count(" |")]
    for (env, method, k), group in cells.items():
        row = [env, LABELS.get(method, method), _layouts_text(k),
               seed_text([r.seed for r in group])]
        for split in GENERALISATION_SPLITS:
            evaluation = f"{split}/paper"
            stats = {}
            for metric in ("performance", "success_rate", "aer"):
                values = [v for r in group if (v := r.values(evaluation, metric)) is not None]
                s = stats[metric] = cell_stats(values)
                if s is not None:
                    csv_rows.append({**stat_row("generalisation", env, method, evaluation,
                                                metric, s), "layouts": "" if k is None else k})
            row += [ci_text(stats["performance"]) if stats["performance"] else "–",
                    fmt(stats["success_rate"].mean, 2) if stats["success_rate"] else "–"]
        lines.append("| " + " | ".join(row) + " |")
    return lines
