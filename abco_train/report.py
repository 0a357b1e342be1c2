"""``abco report RUNS_DIR``: a benchmark of IfO methods, and the paper's tables re-measured.

Writes ``report.md``, ``results.csv`` (the same numbers, one row per statistic) and the plots
into ``--out`` (default ``RUNS_DIR/report``). Numbers come from every
``RUNS_DIR/{env}/{method}/seed{seed}/final.json`` (P, AER, and the environment interactions
each run spent); wall times, reference returns and failures from ``results.jsonl`` and
``bench_log.jsonl`` (:mod:`abco_train.grid`).

The main table (Table 1 re-measured) holds every method found: the built-ins in the order of
:data:`ORDER`, then any other (a user's plugin) alphabetically. Per-cell statistics (mean,
IQM, bootstrap intervals) are :mod:`abco_train.stats`; the aggregates across environments
(rliable) :mod:`abco_train.aggregate`; the published numbers :mod:`abco_train.paper`; the
tables' pieces :mod:`abco_train.report_tables`.

Example:
    >>> table_evaluation("AbcoMaze5x5-v0", "test"), table_evaluation("CartPole-v1")
    ('test/paper', 'episodes')
    >>> method_order(["knn-ifo", "abco", "gaifo", "bc", "attention"])
    ['bc', 'abco', 'gaifo', 'attention', 'knn-ifo']
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import abco_envs
from abco_train import aggregate
from abco_train.config import env_kind
from abco_train.grid import read_results
from abco_train.methods import INTERACTION_KINDS
from abco_train.paper import PAPER_TABLE1, PAPER_TABLE2, PUBLISHED_AER, published
from abco_train.report_plots import plot_label_distributions, plot_performance
from abco_train.stats import CellStats, cell_stats

__all__ = [
    "TABLE1_ENVS", "TABLE1_METHODS", "TABLE2_METHODS", "ORDER", "LABELS", "GOALS", "Run",
    "load_runs", "write_report", "table_evaluation", "method_order", "ReportError",
    "CSV_FIELDS",
]  # fmt: skip

MAZES = abco_envs.MAZE_IDS
TABLE1_ENVS = ("CartPole-v1", "Acrobot-v1", "MountainCar-v0", *MAZES)
#: The built-in methods of the benchmark (Table 1 re-measured), expected on every env: the
#: trainer's method names -> the tables' labels.
TABLE1_METHODS = {"bc": "BC", "bco": "BCO", "bco-alpha": "BCO(α)", "abco": "ABCO(α)",
                  "iupe": "IUPE", "ilpo": "ILPO", "gaifo": "GAIfO"}  # fmt: skip
#: Table 2 rows (ablation, 5x5 maze) -> the trainer's methods. The paper's "BCO" row repeats
#: Table 1's BCO on the 5x5 maze (P -0.112), i.e. BCO(α).
TABLE2_METHODS = {
    "bco-alpha": "BCO(α)", "bco-alpha-torabi": "BCO(α), Torabi", "attention": "Attention",
    "sampling-partial": "Partial sampling",
    "sampling-whole": "Whole sampling", "abco": "ABCO (attention + partial sampling)",
    "abco-whole": "ABCO (attention + whole sampling)",
}  # fmt: skip
TABLE2_ENV = "AbcoMaze5x5-v0"
#: The built-ins in the tables' order; any other method follows, alphabetically.
ORDER = ("bc", "bco", "bco-alpha", "bco-alpha-torabi", "abco", "iupe", "ilpo", "gaifo",
         "attention", "sampling-partial", "sampling-whole", "abco-whole")  # fmt: skip
#: Labels of the main table (a method without one is shown by its name).
LABELS = {**TABLE2_METHODS, **TABLE1_METHODS}

#: The issue's goals (mean over seeds): ABCO's AER >= the paper's and P >= 0.95; IUPE and
#: ILPO at or above their published AER; the seven-method grid within 4 h of wall time.
GOALS = {"aer": {e: PAPER_TABLE1["abco"][e][1] for e in TABLE1_ENVS}, "performance": 0.95,
         "published_aer": PUBLISHED_AER, "wall_s": 4 * 3600.0}  # fmt: skip

CSV_FIELDS = ("table", "env", "method", "evaluation", "metric", "seeds", "mean", "ci_low",
              "ci_high", "iqm", "iqm_ci_low", "iqm_ci_high", "paper")  # fmt: skip


def table_evaluation(env: str, split: str = "train") -> str:
    """The ``final.json`` key of a table's numbers: mazes ``{split}/paper``, else ``episodes``."""
    return f"{split}/paper" if env_kind(env) == "maze" else "episodes"


def method_order(methods: Iterable[str]) -> list[str]:
    """``methods`` in the tables' order: the built-ins of :data:`ORDER`, then the rest."""
    methods = set(methods)
    return [m for m in ORDER if m in methods] + sorted(methods - set(ORDER))


def env_order(env: str) -> tuple[int, str]:
    """Sort key of envs: Table 1's order, then any other env alphabetically."""
    return (TABLE1_ENVS.index(env) if env in TABLE1_ENVS else len(TABLE1_ENVS), env)


class ReportError(ValueError):
    """Nothing to report on, or a bad option (an unknown baseline); the message says which."""


# -- the runs -------------------------------------------------------------------------------


@dataclass
class Run:
    """One cell's run folder: its final evaluation, history and bench row."""

    env: str
    method: str
    seed: int
    path: Path
    final: dict[str, Any] | None
    row: dict[str, Any] = field(default_factory=dict)

    @property
    def status(self) -> str:
        """``ok`` (a result), ``unfinished`` (no final.json), or the status of a run its
        method stopped (e.g. ``idm_at_chance``: no result, by design)."""
        if self.final is None:
            return "unfinished"
        return str(self.final.get("status", "ok"))

    def metrics(self) -> list[dict[str, Any]]:
        """The per-iteration records of ``metrics.jsonl``."""
        path = self.path / "metrics.jsonl"
        if not path.exists():
            return []
        return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]

    def values(self, evaluation: str, metric: str) -> np.ndarray | None:
        """Per-episode values when recorded, else the one score; ``None`` if absent."""
        score = (self.final or {}).get(evaluation)
        if not isinstance(score, dict) or metric not in score:
            return None
        per_episode = score.get("episode_returns" if metric == "aer" else "episode_performance")
        return np.asarray(per_episode if per_episode else [score[metric]], dtype=np.float64)

    def interactions(self, kind: str) -> int | None:
        """Environment interactions of ``kind`` the run spent (``None``: not recorded)."""
        counts = (self.final or {}).get("interactions")
        return int(counts[kind]) if isinstance(counts, dict) and kind in counts else None


def load_runs(runs_dir: str | Path) -> list[Run]:
    """Every run folder ``{env}/{method}/seed{seed}`` under ``runs_dir`` (finished or not)."""
    runs_dir = Path(runs_dir)
    rows = read_results(runs_dir)
    runs = []
    for path in sorted(runs_dir.glob("*/*/seed*")):
        if not path.is_dir() or not path.name[4:].isdigit():
            continue
        final_path = path / "final.json"
        final = json.loads(final_path.read_text()) if final_path.exists() else None
        env, method, seed = path.parent.parent.name, path.parent.name, int(path.name[4:])
        row = rows.get(f"{env}/{method}/seed{seed}", {})
        runs.append(Run(env, method, seed, path, final, row))
    return runs


class Grid:
    """The runs indexed by (env, method), with the expected seeds and methods."""

    def __init__(self, runs: list[Run]) -> None:
        self.runs = runs
        self.done = [r for r in runs if r.status == "ok"]
        self.stopped = [r for r in runs if r.status not in ("ok", "unfinished")]
        self.seeds = sorted({r.seed for r in runs})
        self.methods = method_order({r.method for r in runs})
        self.by_cell: dict[tuple[str, str], list[Run]] = {}
        for r in self.done:
            self.by_cell.setdefault((r.env, r.method), []).append(r)

    @property
    def main_methods(self) -> list[str]:
        """Rows of the main table: Table 1's built-ins and every other method found, except
        Table 2's ablations run only on Table 2's maze (they have their own table)."""
        ablations = set(TABLE2_METHODS) - set(TABLE1_METHODS)
        found = {r.method for r in self.runs
                 if r.method not in ablations or r.env not in (TABLE2_ENV,)}  # fmt: skip
        return method_order(set(TABLE1_METHODS) | found)

    def has(self, env: str, method: str) -> bool:
        """A finished or stopped run of the cell exists."""
        return (env, method) in self.by_cell or any(
            r.env == env and r.method == method for r in self.stopped)

    def by_cell_env(self, env: str) -> list[Run]:
        return [r for r in self.done if r.env == env]

    def stats(self, env: str, method: str, evaluation: str, metric: str) -> CellStats | None:
        groups = [v for r in self.by_cell.get((env, method), [])
                  if (v := r.values(evaluation, metric)) is not None]  # fmt: skip
        return cell_stats(groups)

    def interactions(self, env: str, method: str, kind: str) -> CellStats | None:
        """Interactions of ``kind`` over the cell's finished runs that recorded them."""
        counts = [np.array([float(c)]) for r in self.by_cell.get((env, method), [])
                  if (c := r.interactions(kind)) is not None]  # fmt: skip
        return cell_stats(counts)

    def scores(self, methods: Iterable[str], envs: Iterable[str]
               ) -> dict[str, dict[str, dict[int, float]]]:  # fmt: skip
        """``method -> env -> seed -> P`` of the finished runs (the tables' evaluation)."""
        out: dict[str, dict[str, dict[int, float]]] = {}
        for m in methods:
            for e in envs:
                for r in self.by_cell.get((e, m), []):
                    v = r.values(table_evaluation(e), "performance")
                    if v is not None:
                        out.setdefault(m, {}).setdefault(e, {})[r.seed] = float(v.mean())
        return out


def _settings(runs: list[Run]) -> str:
    """The regime and preset of the grid's runs (from their config.json)."""
    seen: set[tuple[str, str]] = set()
    for r in runs:
        path = r.path / "config.json"
        if path.exists():
            cfg = json.loads(path.read_text())
            seen.add((str(cfg.get("regime", "default")), str(cfg.get("preset", "cpu"))))
    return "; ".join(f"regime {g}, preset {p}" for g, p in sorted(seen)) or "unknown"


def _intro(runs_dir: Path, grid: Grid) -> list[str]:
    kinds = ", ".join(k.replace("_", "-") for k in INTERACTION_KINDS)
    return [
        f"# IfO benchmark: {runs_dir}", "",
        f"{len(grid.done)} finished runs of {len(grid.methods)} method(s), seeds"
        f" {', '.join(map(str, grid.seeds)) or 'none'}; {len(grid.stopped)} run(s) stopped by"
        " their method's health check (e.g. an IDM at chance: no result, counted as '+k"
        " stopped' beside the seeds and summarised under Missing).",
        f"Settings: {_settings(grid.runs)}.",
        "P and AER: mean over seeds with a 95% bootstrap CI, and the IQM. Classic control:",
        "the final evaluation's episodes (unseen seeds); mazes: every layout of the split,",
        "the paper's protocol (4th visit to a cell ends the episode with return -1).",
        f"Interactions ({kinds}): environment steps a run spent, by kind,",
        "mean per finished run; evaluation episodes are not counted; '–': not recorded.",
        "", "CI scheme: two-stage percentile bootstrap (10,000 replicates, numpy, seed 0): seeds",
        "resampled with replacement, then each drawn seed's episodes when final.json holds",
        "per-episode values (else seeds only). IQM: mean of the per-seed scores after cutting",
        "floor(n/4) at each end. Published numbers: BC, BCO(α), ABCO(α) from Monteiro et al.,",
        "IJCNN 2020, Tables 1 and 2; the AER of IUPE and ILPO as the IUPE authors report them",
        "(Gavenski et al., BMVC 2020); none for GAIfO or a method of your own.",
    ]  # fmt: skip


def write_report(runs_dir: str | Path, out: str | Path | None = None,
                 labels_env: str = TABLE2_ENV, baseline: str | None = None,
                 ) -> dict[str, Path]:  # fmt: skip
    """Write ``report.md``, ``results.csv`` and the plots of the grid in ``runs_dir``.

    Args:
        runs_dir: The ``abco bench --out`` folder.
        out: Where to write (default ``runs_dir/report``).
        labels_env: Env of the IDM label-distribution plot (the paper's Figure 4: 5x5 maze).
        baseline: Reference method of the probability of improvement (default ``abco``; a
            name given must be a method of the grid).

    Returns:
        The written files by name (``report``, ``csv``, and the plots that had data:
        ``performance``, ``labels``, ``profile``).

    Raises:
        ReportError: ``runs_dir`` is not a folder, holds no run folders, or has no method
            ``baseline``.
    """
    from abco_train import report_tables as tables

    runs_dir = Path(runs_dir)
    if not runs_dir.is_dir():
        raise ReportError(f"no such folder {runs_dir}")
    runs = load_runs(runs_dir)
    if not runs:
        raise ReportError(f"{runs_dir} holds no run folders ({{env}}/{{method}}/seed{{n}}); "
                          "is it an `abco bench --out` folder?")  # fmt: skip
    grid = Grid(runs)
    if baseline is not None and baseline not in grid.methods:
        raise ReportError(f"unknown baseline {baseline!r}: not a method of {runs_dir}; methods"
                          f" found: {', '.join(grid.methods)}")  # fmt: skip
    baseline = baseline or "abco"
    out = Path(out) if out is not None else runs_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    csv_rows: list[dict[str, Any]] = []
    wall, wall_lines = tables.wall(runs_dir, grid)
    main = grid.main_methods
    label = {m: LABELS.get(m, m) for m in grid.methods + main}
    t1 = [(e, m, label[m], published(m, e)) for e in TABLE1_ENVS for m in main
          if grid.has(e, m)]  # fmt: skip
    t1_test = [(e, m, label[m], None) for e in MAZES for m in main if grid.has(e, m)]
    t2 = [(TABLE2_ENV, m, lab, PAPER_TABLE2.get(m)) for m, lab in TABLE2_METHODS.items()
          if grid.has(TABLE2_ENV, m)]  # fmt: skip
    t2_test = [(e, m, lab, None) for e, m, lab, _ in t2]
    agg_lines, agg_rows, profile_png = aggregate.section(
        grid.scores(main, TABLE1_ENVS), TABLE1_ENVS, baseline, out, label,
        evaluation="train/paper (mazes), episodes")  # fmt: skip
    means = {e: {m: s.mean for m in main
                 if (s := grid.stats(e, m, table_evaluation(e), "performance"))}
             for e in TABLE1_ENVS}  # fmt: skip
    files: dict[str, Path] = {}
    perf_png = plot_performance(grid.by_cell, out / "performance_per_iteration.png", env_order)
    labels_png = plot_label_distributions(grid.by_cell, labels_env, ("bco-alpha", "abco"),
                                          out / "idm_label_distribution.png")  # fmt: skip
    empty = ["No finished or stopped run of these cells."]
    md = [*_intro(runs_dir, grid),
          "", "## Goals (mean over seeds)", "", *tables.goals(grid, wall),
          "", "## Table 1 re-measured: every method, train split (the paper's protocol)", "",
          *(tables.table(grid, t1, "train", csv_rows, "table1", counts=True) if t1 else empty),
          "", f"## Aggregates across the {len(TABLE1_ENVS)} environments (rliable)", "",
          *agg_lines, "", "## Which environments separate methods", "",
          *aggregate.separation(means, TABLE1_ENVS, label),
          "", "## Table 1, mazes on the held-out test split", "",
          *(tables.table(grid, t1_test, "test", csv_rows, "table1-test") if t1_test else empty),
          "", "## Table 2: ablation on the 5x5 maze, train split", "",
          *(tables.table(grid, t2, "train", csv_rows, "table2") if t2 else empty),
          "", "Table 2's BCO row is BCO(α) (the paper's Table 2 BCO repeats Table 1's).",
          "", "### Table 2 on the test split", "",
          *(tables.table(grid, t2_test, "test", csv_rows, "table2-test") if t2 else empty),
          "", "## Missing, unfinished, failed or stopped cells", "", *tables.missing(grid),
          "", "## Every (env, method) found: success rate and wall time", "",
          "Train split; every evaluation of every cell is in the CSV (`table` = `all`).", "",
          *tables.all_runs(grid, csv_rows),
          "", "## Reference returns (P = (R - random) / (expert - random))", "",
          "Mazes normalise per layout; the means over each split's layouts are shown.", "",
          *tables.references(grid), "", "## Wall time", "", *wall_lines,
          "", "## Plots", ""]  # fmt: skip
    csv_rows += agg_rows
    for name, png, caption in (
        ("performance", perf_png, "P per iteration (band: min..max across seeds)"),
        ("labels", labels_png, f"IDM label distribution, BCO(α) vs ABCO on {labels_env}"),
    ):  # fmt: skip
        if png is None:
            md.append(f"- {caption}: no runs to plot.")
        else:
            files[name] = png
            md.append(f"![{caption}]({png.name})")
    if profile_png is not None:
        files["profile"] = profile_png
    files["report"] = out / "report.md"
    files["report"].write_text("\n".join(md) + "\n")
    files["csv"] = out / "results.csv"
    with files["csv"].open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        writer.writeheader()
        writer.writerows(csv_rows)
    return files
