"""``abco report RUNS_DIR``: the paper's tables re-measured from an ``abco bench`` grid.

Writes ``report.md``, ``results.csv`` (the same numbers, one row per statistic) and two plots
into ``--out`` (default ``RUNS_DIR/report``). Numbers come from every
``RUNS_DIR/{env}/{method}/seed{seed}/final.json``; wall times, reference returns and failures
from ``results.jsonl`` and ``bench_log.jsonl`` (:mod:`abco_train.grid`).

Statistics (mean, IQM, bootstrap intervals) are :mod:`abco_train.stats`; the published
numbers :mod:`abco_train.paper`.

Example:
    >>> table_evaluation("AbcoMaze5x5-v0", "test"), table_evaluation("CartPole-v1")
    ('test/paper', 'episodes')
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import abco_envs
from abco_train.config import env_kind
from abco_train.grid import read_results
from abco_train.paper import PAPER_TABLE1, PAPER_TABLE2
from abco_train.stats import CellStats, cell_stats

__all__ = [
    "TABLE1_ENVS", "TABLE1_METHODS", "TABLE2_METHODS", "GOALS", "Run", "load_runs",
    "write_report", "table_evaluation", "ReportError",
]  # fmt: skip

MAZES = abco_envs.MAZE_IDS
TABLE1_ENVS = ("CartPole-v1", "Acrobot-v1", "MountainCar-v0", *MAZES)
#: Table 1 rows -> the trainer's methods (abco_train.abco.VARIANTS).
TABLE1_METHODS = {"bc": "BC", "bco-alpha": "BCO(α)", "bco-alpha-torabi": "BCO(α), Torabi",
                  "abco": "ABCO(α)"}  # fmt: skip
#: Table 2 rows (ablation, 5x5 maze) -> the trainer's methods. The paper's "BCO" row repeats
#: Table 1's BCO on the 5x5 maze (P -0.112), i.e. BCO(α).
TABLE2_METHODS = {
    "bco-alpha": "BCO(α)", "bco-alpha-torabi": "BCO(α), Torabi", "attention": "Attention",
    "sampling-partial": "Partial sampling",
    "sampling-whole": "Whole sampling", "abco": "ABCO (attention + partial sampling)",
    "abco-whole": "ABCO (attention + whole sampling)",
}  # fmt: skip
TABLE2_ENV = "AbcoMaze5x5-v0"

#: The issue's goals for ABCO (mean over seeds): AER >= the paper's, P >= 0.95, 2 h of wall.
GOALS = {"aer": {e: PAPER_TABLE1["abco"][e][1] for e in TABLE1_ENVS}, "performance": 0.95,
         "wall_s": 2 * 3600.0}  # fmt: skip


def table_evaluation(env: str, split: str = "train") -> str:
    """The ``final.json`` key of a table's numbers: mazes ``{split}/paper``, else ``episodes``."""
    return f"{split}/paper" if env_kind(env) == "maze" else "episodes"


class ReportError(ValueError):
    """The folder holds nothing to report on; the message names it."""


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


class _Grid:
    """The runs indexed by (env, method), with the expected seeds."""

    def __init__(self, runs: list[Run]) -> None:
        self.runs = runs
        self.done = [r for r in runs if r.status == "ok"]
        self.stopped = [r for r in runs if r.status not in ("ok", "unfinished")]
        self.seeds = sorted({r.seed for r in runs})
        self.by_cell: dict[tuple[str, str], list[Run]] = {}
        for r in self.done:
            self.by_cell.setdefault((r.env, r.method), []).append(r)

    def by_cell_env(self, env: str) -> list[Run]:
        return [r for r in self.done if r.env == env]

    def stats(self, env: str, method: str, evaluation: str, metric: str) -> CellStats | None:
        groups = [v for r in self.by_cell.get((env, method), [])
                  if (v := r.values(evaluation, metric)) is not None]  # fmt: skip
        return cell_stats(groups)


# -- tables ---------------------------------------------------------------------------------


def _fmt(x: float | None, digits: int = 3) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _ci(s: CellStats | None) -> str:
    if s is None:
        return "missing"
    return f"{_fmt(s.mean)} [{_fmt(s.ci[0])}, {_fmt(s.ci[1])}]"


def _table(grid: _Grid, rows: list[tuple[str, str, str, tuple[float, float] | None]],
           split: str, csv_rows: list[dict[str, Any]], name: str) -> list[str]:  # fmt: skip
    """Markdown rows ``(env, method, label, paper (P, AER))``; CSV rows appended."""
    paper_cols = any(p is not None for *_, p in rows)
    head = "| Env | Method | Seeds | P mean [95% CI] | P IQM |"
    head += " P paper |" if paper_cols else ""
    head += " AER mean [95% CI] | AER IQM |" + (" AER paper |" if paper_cols else "")
    lines = [head, "|" + "---|" * head.count(" |")]
    for env, method, label, paper in rows:
        evaluation = table_evaluation(env, split)
        cells = [env, label]
        p_stats = grid.stats(env, method, evaluation, "performance")
        a_stats = grid.stats(env, method, evaluation, "aer")
        stopped = sum(r.env == env and r.method == method for r in grid.stopped)
        cells.append(str(p_stats.n if p_stats else 0) + (f" (+{stopped} stopped)" if stopped
                                                         else ""))  # fmt: skip
        for k, (metric, s) in enumerate((("performance", p_stats), ("aer", a_stats))):
            cells += [_ci(s), _fmt(s.iqm) if s else "–"]
            if paper_cols:
                cells.append(_fmt(paper[k]) if paper else "–")
            csv_rows.append({
                "table": name, "env": env, "method": method, "evaluation": evaluation,
                "metric": metric, "seeds": s.n if s else 0, "mean": s.mean if s else "",
                "ci_low": s.ci[0] if s else "", "ci_high": s.ci[1] if s else "",
                "iqm": s.iqm if s else "", "iqm_ci_low": s.iqm_ci[0] if s else "",
                "iqm_ci_high": s.iqm_ci[1] if s else "", "paper": paper[k] if paper else "",
            })  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _goals(grid: _Grid, wall: float | None) -> list[str]:
    lines = ["| Env | ABCO AER | goal (paper's ABCO) | AER verdict | ABCO P | P verdict |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for env in TABLE1_ENVS:
        ev = table_evaluation(env)
        aer, perf = grid.stats(env, "abco", ev, "aer"), grid.stats(env, "abco", ev, "performance")
        goal = GOALS["aer"][env]
        verdicts = []
        stopped = sum(r.env == env and r.method == "abco" for r in grid.stopped)
        for s, target in ((aer, goal), (perf, GOALS["performance"])):
            if stopped:
                verdicts.append(f"**not met: {stopped} run(s) stopped**")
            elif s is None:
                verdicts.append("not run")
            elif s.mean >= target - 1e-9:
                verdicts.append("met")
            else:
                verdicts.append(f"**short by {target - s.mean:.3f}**")
        lines.append(f"| {env} | {_ci(aer)} | {goal:.3f} | {verdicts[0]} | {_ci(perf)} |"
                     f" {verdicts[1]} (goal {GOALS['performance']:.2f}) |")  # fmt: skip
    if wall is None:
        lines.append("\nGrid wall time: unknown (no bench_log.jsonl).")
    else:
        verdict = ("met" if wall <= GOALS["wall_s"] else
                   f"**over by {(wall - GOALS['wall_s']) / 60:.1f} min**")  # fmt: skip
        lines.append(f"\nGrid wall time {wall / 60:.1f} min against the goal of"
                     f" {GOALS['wall_s'] / 3600:.0f} h: {verdict}.")  # fmt: skip
    return lines


def _missing(grid: _Grid) -> list[str]:
    expected = [(e, m) for e in TABLE1_ENVS for m in TABLE1_METHODS]
    expected += [(TABLE2_ENV, m) for m in TABLE2_METHODS if (TABLE2_ENV, m) not in expected]
    seeds = grid.seeds or [0, 1, 2, 3, 4]
    found = {(r.env, r.method, r.seed) for r in grid.done}
    lines = []
    for env, method in expected:
        lost = [s for s in seeds if (env, method, s) not in found]
        if lost:
            what = "all seeds" if len(lost) == len(seeds) else "seeds " + ", ".join(map(str, lost))
            lines.append(f"- {env} / {method}: missing {what}")
    for r in grid.stopped:
        lines.append(f"- {r.env} / {r.method} / seed {r.seed}: stopped, {r.status} "
                     f"({(r.final or {}).get('message', '')})")
    for r in grid.runs:
        if r.final is None:
            state = "failed" if r.row.get("status") == "failed" else "unfinished"
            lines.append(f"- {r.env} / {r.method} / seed {r.seed}: {state}"
                         + (f" ({r.row.get('error')})" if r.row.get("error") else ""))
    if len(seeds) < 5:
        lines.append(f"- only {len(seeds)} seed(s) per cell; the issue asks for at least 5")
    return lines or ["None: every cell of both tables has every seed."]


def _references(grid: _Grid) -> list[str]:
    lines = ["| Env | Split | Expert return | Random return | Layouts |", "|---|---|---|---|---|"]
    envs = sorted({r.env for r in grid.done}, key=_env_order)
    for env in envs:
        ref = next((r.row["reference"] for r in grid.by_cell_env(env)
                    if isinstance(r.row.get("reference"), dict)
                    and "expert" in r.row["reference"]), None)  # fmt: skip
        if ref is None:
            lines.append(f"| {env} | – | unknown | unknown | – |")
            continue
        splits = [s for s in ("train", "test") if s in ref]
        if not splits:
            lines.append(f"| {env} | episodes | {_fmt(ref['expert'])} | {_fmt(ref['random'])} |"
                         " – |")  # fmt: skip
        for s in splits:
            lines.append(f"| {env} | {s} | {_fmt(ref[s]['expert'])} | {_fmt(ref[s]['random'])}"
                         f" | {ref[s]['layouts']} |")  # fmt: skip
    return lines


def _env_order(env: str) -> tuple[int, str]:
    return (TABLE1_ENVS.index(env) if env in TABLE1_ENVS else len(TABLE1_ENVS), env)


def _all_runs(grid: _Grid, csv_rows: list[dict[str, Any]]) -> list[str]:
    """Every (env, method) found, every evaluation in the CSV; the headline one in Markdown."""
    lines = ["| Env | Method | Seeds | P mean [95% CI] | AER mean [95% CI] | Success |"
             " Wall per seed (s) |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for env, method in sorted(grid.by_cell, key=lambda k: (_env_order(k[0]), k[1])):
        runs = grid.by_cell[(env, method)]
        evaluations = sorted({k for r in runs for k, v in (r.final or {}).items()
                              if isinstance(v, dict) and "performance" in v})  # fmt: skip
        for ev in evaluations:
            for metric in ("performance", "aer", "success_rate"):
                s = grid.stats(env, method, ev, metric)
                if s is not None:
                    csv_rows.append({
                        "table": "all", "env": env, "method": method, "evaluation": ev,
                        "metric": metric, "seeds": s.n, "mean": s.mean, "ci_low": s.ci[0],
                        "ci_high": s.ci[1], "iqm": s.iqm, "iqm_ci_low": s.iqm_ci[0],
                        "iqm_ci_high": s.iqm_ci[1], "paper": "",
                    })  # fmt: skip
        ev = table_evaluation(env)
        walls = [r.row["wall_s"] for r in runs if r.row.get("wall_s") is not None]
        success = grid.stats(env, method, ev, "success_rate")
        perf, aer = grid.stats(env, method, ev, "performance"), grid.stats(env, method, ev, "aer")
        lines.append(
            f"| {env} | {method} | {len(runs)} | {_ci(perf)} | {_ci(aer)}"
            f" | {_fmt(success.mean if success else None, 2)}"
            f" | {_fmt(float(np.mean(walls)) if walls else None, 1)} |"
        )
    return lines


def _wall(runs_dir: Path, grid: _Grid) -> tuple[float | None, list[str]]:
    log = runs_dir / "bench_log.jsonl"
    sessions = ([json.loads(x) for x in log.read_text().splitlines() if x.strip()]
                if log.exists() else [])  # fmt: skip
    ran = [s for s in sessions if s.get("ran") or s.get("failed")]
    wall = float(sum(s["wall_s"] for s in ran)) if sessions else None
    cell_wall = sum(r.row.get("wall_s") or 0.0 for r in grid.done)
    lines = [f"- Grid wall time: {_fmt(wall, 1) if wall is not None else 'unknown'} s"
             f" ({_fmt(wall / 3600 if wall is not None else None, 2)} h) over {len(ran)}"
             " `abco bench` session(s) that ran cells.",
             f"- Sum of the cells' own wall times: {cell_wall:.1f} s over {len(grid.done)} cells."]
    for s in ran:
        lines.append(f"  - {s.get('started')}: {s['wall_s']:.1f} s, backend {s.get('backend')},"
                     f" jobs {s.get('jobs')}, threads {s.get('threads')}, ran {s.get('ran')},"
                     f" skipped {s.get('skipped')}, failed {len(s.get('failed', []))}")
    return wall, lines


# -- plots ----------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _series(runs: list[Run], pick: Any) -> np.ndarray:
    """``(seeds, iterations)`` of ``pick(record)`` (NaN where a run has fewer iterations)."""
    histories = [r.metrics() for r in runs]
    length = max((len(h) for h in histories), default=0)
    out = np.full((len(runs), length), np.nan)
    for i, h in enumerate(histories):
        for rec in h:
            value = pick(rec)
            if value is not None:
                out[i, rec["iteration"]] = value
    return out


def plot_performance(grid: _Grid, path: Path) -> Path | None:
    """P of the per-iteration evaluation, mean over seeds with the min-max band, per env."""
    envs = sorted({e for e, _ in grid.by_cell}, key=_env_order)
    if not envs:
        return None
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    cols = min(3, len(envs))
    rows = -(-len(envs) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, env in zip(axes.flat, envs):
        for method in sorted(m for e, m in grid.by_cell if e == env):
            p = _series(grid.by_cell[(env, method)], lambda rec: rec["eval"]["performance"])
            if p.size == 0:
                continue
            its = np.arange(p.shape[1])
            with np.errstate(all="ignore"):
                mean, lo, hi = np.nanmean(p, 0), np.nanmin(p, 0), np.nanmax(p, 0)
            (line,) = ax.plot(its, mean, marker="o", ms=3, label=method)
            ax.fill_between(its, lo, hi, color=line.get_color(), alpha=0.2, lw=0)
        ax.set_title(env, fontsize=9)
        ax.set_xlabel("iteration")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("P")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(envs) :]:
        ax.axis("off")
    fig.suptitle("P per iteration: mean over seeds, band = min..max across seeds", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _share(record: dict[str, Any], action: int, n_actions: int) -> float | None:
    dist = record.get("label_distribution")
    return dist[action] if dist and len(dist) == n_actions else None


def plot_label_distributions(grid: _Grid, env: str, methods: Sequence[str], path: Path
                             ) -> Path | None:  # fmt: skip
    """The IDM's predicted action shares on the expert data per iteration (mean over seeds)."""
    from abco_train.plots import ACTION_NAMES

    found = [m for m in methods if (env, m) in grid.by_cell]
    if not found:
        return None
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, len(found), figsize=(5 * len(found), 3.4), squeeze=False)
    for ax, method in zip(axes[0], found):
        runs = grid.by_cell[(env, method)]
        dists = [rec.get("label_distribution") for r in runs for rec in r.metrics()]
        n_actions = max((len(d) for d in dists if d), default=0)
        truth = next((r.row.get("reference", {}).get("expert_actions") for r in runs
                      if isinstance(r.row.get("reference"), dict)), None)  # fmt: skip
        names = ACTION_NAMES.get(n_actions, [str(a) for a in range(n_actions)])
        for a in range(n_actions):
            share = _series(runs, lambda rec, a=a, k=n_actions: _share(rec, a, k))
            with np.errstate(all="ignore"):
                (line,) = ax.plot(np.arange(share.shape[1]), np.nanmean(share, 0), marker="o",
                                  ms=3, label=names[a])  # fmt: skip
            if truth:
                ax.axhline(truth[a], color=line.get_color(), ls="--", lw=1)
        ax.set_title(f"{method} on {env} (dashed: expert's true shares)", fontsize=9)
        ax.set_xlabel("iteration")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("share of IDM labels")
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


# -- the report -----------------------------------------------------------------------------

def _settings(runs: list[Run]) -> str:
    """The regime and preset of the grid's runs (from their config.json)."""
    seen: set[tuple[str, str]] = set()
    for r in runs:
        path = r.path / "config.json"
        if path.exists():
            cfg = json.loads(path.read_text())
            seen.add((str(cfg.get("regime", "default")), str(cfg.get("preset", "cpu"))))
    return "; ".join(f"regime {g}, preset {p}" for g, p in sorted(seen)) or "unknown"


CSV_FIELDS = ("table", "env", "method", "evaluation", "metric", "seeds", "mean", "ci_low",
              "ci_high", "iqm", "iqm_ci_low", "iqm_ci_high", "paper")  # fmt: skip


def write_report(runs_dir: str | Path, out: str | Path | None = None,
                 labels_env: str = TABLE2_ENV) -> dict[str, Path]:  # fmt: skip
    """Write ``report.md``, ``results.csv`` and the plots of the grid in ``runs_dir``.

    Args:
        runs_dir: The ``abco bench --out`` folder.
        out: Where to write (default ``runs_dir/report``).
        labels_env: Env of the IDM label-distribution plot (the paper's Figure 4: 5x5 maze).

    Returns:
        The written files by name (``report``, ``csv``, and the plots that had data).

    Raises:
        ReportError: ``runs_dir`` is not a folder, or holds no run folders.
    """
    runs_dir = Path(runs_dir)
    if not runs_dir.is_dir():
        raise ReportError(f"no such folder {runs_dir}")
    runs = load_runs(runs_dir)
    if not runs:
        raise ReportError(f"{runs_dir} holds no run folders ({{env}}/{{method}}/seed{{n}}); "
                          "is it an `abco bench --out` folder?")  # fmt: skip
    out = Path(out) if out is not None else runs_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    grid = _Grid(runs)
    csv_rows: list[dict[str, Any]] = []
    wall, wall_lines = _wall(runs_dir, grid)
    t1 = [(e, m, label, PAPER_TABLE1.get(m, {}).get(e)) for e in TABLE1_ENVS
          for m, label in TABLE1_METHODS.items()]  # fmt: skip
    t1_test = [(e, m, label, None) for e in MAZES for m, label in TABLE1_METHODS.items()]
    t2 = [(TABLE2_ENV, m, label, PAPER_TABLE2.get(m)) for m, label in TABLE2_METHODS.items()]
    t2_test = [(TABLE2_ENV, m, label, None) for m, label in TABLE2_METHODS.items()]
    files: dict[str, Path] = {}
    perf_png = plot_performance(grid, out / "performance_per_iteration.png")
    labels_png = plot_label_distributions(grid, labels_env, ("bco-alpha", "abco"),
                                          out / "idm_label_distribution.png")  # fmt: skip

    md = [f"# ABCO benchmark: {runs_dir}", "",
          f"{len(grid.done)} finished runs, seeds {', '.join(map(str, grid.seeds)) or 'none'};"
          f" {len(grid.stopped)} run(s) stopped by their method's health check (e.g. an IDM at"
          " chance: no result, counted as '+k stopped' beside the seeds and listed below).",
          f"Settings: {_settings(runs)}.",
          "P and AER: mean over seeds with a 95% bootstrap CI, and the IQM. Classic control:",
          "the final evaluation's episodes (unseen seeds); mazes: every layout of the split,",
          "the paper's protocol (4th visit to a cell ends the episode with return -1).", "",
          "CI scheme: two-stage percentile bootstrap (10,000 replicates, numpy, seed 0): seeds",
          "resampled with replacement, then each drawn seed's episodes when final.json holds",
          "per-episode values (else seeds only). IQM: mean of the per-seed scores after cutting",
          "floor(n/4) at each end. Paper numbers: Monteiro et al., IJCNN 2020, Tables 1 and 2.",
          "", "## Goals for ABCO (mean over seeds)", "", *_goals(grid, wall),
          "", "## Table 1: train split (the paper's protocol)", "",
          *_table(grid, t1, "train", csv_rows, "table1"),
          "", "## Table 1, mazes on the held-out test split", "",
          *_table(grid, t1_test, "test", csv_rows, "table1-test"),
          "", "## Table 2: ablation on the 5x5 maze, train split", "",
          *_table(grid, t2, "train", csv_rows, "table2"),
          "", "Table 2's BCO row is BCO(α) (the paper's Table 2 BCO repeats Table 1's).",
          "", "### Table 2 on the test split", "",
          *_table(grid, t2_test, "test", csv_rows, "table2-test"),
          "", "## Every method found (train split; all evaluations in the CSV)", "",
          *_all_runs(grid, csv_rows),
          "", "## Missing, unfinished, failed or stopped cells", "", *_missing(grid),
          "", "## Reference returns (P = (R - random) / (expert - random))", "",
          "Mazes normalise per layout; the means over each split's layouts are shown.", "",
          *_references(grid), "", "## Wall time", "", *wall_lines, "", "## Plots", ""]  # fmt: skip
    for name, png, caption in (
        ("performance", perf_png, "P per iteration (band: min..max across seeds)"),
        ("labels", labels_png, f"IDM label distribution, BCO(α) vs ABCO on {labels_env}"),
    ):  # fmt: skip
        if png is None:
            md.append(f"- {caption}: no runs to plot.")
        else:
            files[name] = png
            md.append(f"![{caption}]({png.name})")
    files["report"] = out / "report.md"
    files["report"].write_text("\n".join(md) + "\n")
    files["csv"] = out / "results.csv"
    with files["csv"].open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        writer.writeheader()
        writer.writerows(csv_rows)
    return files
