"""The Markdown tables and summaries of ``abco report`` (:mod:`abco_train.report.write`).

Each function takes the grid (:class:`abco_train.report.runs.Grid`) and returns Markdown lines;
the tables also append their numbers to the CSV rows (one row per statistic).

Example:
    >>> seed_text([0, 1, 2, 4])
    'seeds 0-2, 4'
    >>> count_text(123456.0), count_text(None)
    ('123,456', '–')
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from abco_train.bench.records import Skipped, escape
from abco_train.bench.results_log import read_log
from abco_train.methods.base import INTERACTION_KINDS
from abco_train.report.runs import (
    GOALS,
    LABELS,
    TABLE1_ENVS,
    TABLE1_METHODS,
    TABLE2_ENV,
    TABLE2_METHODS,
    Grid,
    env_order,
    method_order,
    table_evaluation,
)
from abco_train.report.stats import CellStats

__all__ = ["table", "goals", "missing", "references", "all_runs", "wall", "GridWall", "seed_text",
           "count_text", "fmt", "ci_text", "stat_row"]  # fmt: skip

#: Column titles of the interaction kinds.
KIND_TITLES = {"pre_demonstration": "Pre-demo", "post_demonstration": "Post-demo", "rl": "RL",
               "remapping": "Remap"}  # fmt: skip


def fmt(x: float | None, digits: int = 3) -> str:
    """``x`` with ``digits`` decimals; ``–`` when unknown or not finite."""
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def ci_text(s: CellStats | None) -> str:
    """``mean [low, high]`` of a cell's statistics; ``missing`` without any."""
    if s is None:
        return "missing"
    return f"{fmt(s.mean)} [{fmt(s.ci[0])}, {fmt(s.ci[1])}]"


def count_text(x: float | None) -> str:
    """An interaction count (mean per run) with thousands separators; ``–`` when unknown."""
    return "–" if x is None else f"{x:,.0f}"


def seed_text(seeds: Sequence[int]) -> str:
    """``seed 3`` or ``seeds 0-2, 4``: runs of consecutive seeds as ranges."""
    seeds = sorted(seeds)
    parts, start = [], 0
    for i in range(1, len(seeds) + 1):
        if i == len(seeds) or seeds[i] != seeds[i - 1] + 1:
            a, b = seeds[start], seeds[i - 1]
            parts.append(str(a) if a == b else f"{a}-{b}")
            start = i
    return ("seed " if len(seeds) == 1 else "seeds ") + ", ".join(parts)


def stat_row(table: str, env: str, method: str, evaluation: str, metric: str,
             s: CellStats | None, paper: float | None = None) -> dict[str, Any]:  # fmt: skip
    """One row of ``results.csv``: a statistic of a cell (empty numbers without runs)."""
    return {
        "table": table, "env": env, "method": method, "evaluation": evaluation,
        "metric": metric, "seeds": s.n if s else 0, "mean": s.mean if s else "",
        "ci_low": s.ci[0] if s else "", "ci_high": s.ci[1] if s else "",
        "iqm": s.iqm if s else "", "iqm_ci_low": s.iqm_ci[0] if s else "",
        "iqm_ci_high": s.iqm_ci[1] if s else "", "paper": "" if paper is None else paper,
    }  # fmt: skip


def table(grid: Grid, rows: Sequence[tuple[str, str, str, tuple[float | None, float] | None]],
          split: str, csv_rows: list[dict[str, Any]], name: str, counts: bool = False,
          ) -> list[str]:  # fmt: skip
    """Markdown rows ``(env, method, label, published (P, AER))``; CSV rows appended.

    ``counts``: the interaction columns (mean per finished run) too, and their CSV rows
    (``evaluation`` = ``training``, ``metric`` = ``interactions/{kind}``).
    """
    paper_cols = any(p is not None for *_, p in rows)
    head = "| Env | Method | Seeds | P mean [95% CI] | P IQM |"
    head += " P paper |" if paper_cols else ""
    head += " AER mean [95% CI] | AER IQM |" + (" AER paper |" if paper_cols else "")
    head += "".join(f" {KIND_TITLES[k]} |" for k in INTERACTION_KINDS) if counts else ""
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
            published = paper[k] if paper else None
            cells += [ci_text(s), fmt(s.iqm) if s else "–"]
            if paper_cols:
                cells.append(fmt(published))
            csv_rows.append(stat_row(name, env, method, evaluation, metric, s, published))
        if counts:
            for kind in INTERACTION_KINDS:
                s = grid.interactions(env, method, kind)
                cells.append(count_text(s.mean if s else None))
                if s is not None:
                    csv_rows.append(stat_row(name, env, method, "training",
                                              f"interactions/{kind}", s))  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _verdict(s: CellStats | None, target: float, stopped: int) -> str:
    if stopped:
        return f"**not met: {stopped} run(s) stopped**"
    if s is None:
        return "not run"
    return "met" if s.mean >= target - 1e-9 else f"**short by {target - s.mean:.3f}**"


def goals(grid: Grid, wall_s: float | None) -> list[str]:
    """ABCO's goals per env; IUPE and ILPO against their published AER; the grid's wall time.

    An env where a method has no run gets no row: one line names those envs. The wall-time
    goal is the seven-method grid's: it is judged only on a grid with runs of every Table 1
    method.
    """
    rows, not_run = [], []
    for env in TABLE1_ENVS:
        ev = table_evaluation(env)
        aer, perf = grid.stats(env, "abco", ev, "aer"), grid.stats(env, "abco", ev, "performance")
        goal = GOALS["aer"][env]
        stopped = sum(r.env == env and r.method == "abco" for r in grid.stopped)
        if aer is None and perf is None and not stopped:
            not_run.append(env)
            continue
        rows.append(f"| {env} | {ci_text(aer)} | {goal:.3f} | {_verdict(aer, goal, stopped)} |"
                    f" {ci_text(perf)} | {_verdict(perf, GOALS['performance'], stopped)} (goal"
                    f" {GOALS['performance']:.2f}) |")  # fmt: skip
    lines = ["ABCO(α): AER at or above the paper's ABCO, P at or above"
             f" {GOALS['performance']:.2f}.", "",
             *_goal_table("| Env | ABCO AER | goal (paper's ABCO) | AER verdict | ABCO P |"
                          " P verdict |", rows, {"ABCO(α)": not_run}),
             "", "IUPE and ILPO: AER at or above their published AER on every environment"
             " where one exists (GAIfO has none).", ""]  # fmt: skip
    rows, missing_envs = [], {}
    for method in method_order(GOALS["published_aer"]):
        published = GOALS["published_aer"][method]
        name = TABLE1_METHODS.get(method, method)
        for env in TABLE1_ENVS:
            if env not in published:
                continue
            aer = grid.stats(env, method, table_evaluation(env), "aer")
            stopped = sum(r.env == env and r.method == method for r in grid.stopped)
            if aer is None and not stopped:
                missing_envs.setdefault(name, []).append(env)
                continue
            rows.append(f"| {env} | {name} | {ci_text(aer)} | {published[env]:.3f} |"
                        f" {_verdict(aer, published[env], stopped)} |")  # fmt: skip
    lines += _goal_table("| Env | Method | AER mean [95% CI] | published AER | verdict |", rows,
                         missing_envs)  # fmt: skip
    seeds = grid.seeds or [0, 1, 2, 3, 4]  # as missing() counts them
    found = {(r.env, r.method, r.seed) for r in grid.done}
    without = sum(any((env, m, s) not in found for s in seeds)
                  for env in TABLE1_ENVS for m in TABLE1_METHODS)  # fmt: skip
    if not set(TABLE1_METHODS) <= {r.method for r in grid.runs}:
        return lines  # a grid of the user's own: the seven-method grid's time goal is not its
    if wall_s is None:
        lines.append("\nGrid wall time: unknown (no bench_log.jsonl).")
    elif without and wall_s <= GOALS["wall_s"]:  # a partial grid's time says nothing of the whole's
        lines.append(f"\nGrid wall time so far {wall_s / 60:.1f} min (sessions that ran cells);"
                     f" the goal of {GOALS['wall_s'] / 3600:.0f} h for the seven-method grid is"
                     f" **not decided**: {without} of its {len(TABLE1_ENVS) * len(TABLE1_METHODS)}"
                     " (env, method) cells lack some seeds.")  # fmt: skip
    else:
        goal = GOALS["wall_s"]
        verdict = "met" if wall_s <= goal else f"**over by {(wall_s - goal) / 60:.1f} min**"
        lines.append(f"\nGrid wall time {wall_s / 60:.1f} min against the goal of"
                     f" {goal / 3600:.0f} h for the seven-method grid: {verdict}.")  # fmt: skip
    return lines


def _goal_table(head: str, rows: list[str], not_run: dict[str, list[str]]) -> list[str]:
    """A goal table (none without rows), then one line per method naming the envs where it has
    no run (no verdict there)."""
    lines = [head, "|" + "---|" * head.count(" |"), *rows] if rows else []
    notes = [f"- {name}: no run on"
             f" {'any environment' if len(envs) == len(TABLE1_ENVS) else ', '.join(envs)}"
             " in this grid." for name, envs in not_run.items() if envs]  # fmt: skip
    return lines + ([""] if lines and notes else []) + notes


def _cells(n: int) -> str:
    return f"{n} cell" + ("" if n == 1 else "s")


def _expected(grid: Grid) -> dict[str, list[str]]:
    """Envs each method of the grid is expected on: every env of the grid (a Table 2 ablation
    on the 5x5 maze only)."""
    envs = sorted({r.env for r in grid.runs}, key=env_order)
    methods = {r.method for r in grid.runs}
    expected = {m: [e for e in envs if m not in TABLE2_METHODS or m in grid.main_methods
                    or e == TABLE2_ENV] for m in methods}  # fmt: skip
    return {m: expected[m] for m in method_order(expected) if expected[m]}


def missing(grid: Grid) -> list[str]:
    """The cells without a finished run, summarised per method; then why, where known."""
    seeds = grid.seeds or [0, 1, 2, 3, 4]
    found = {(r.env, r.method, r.seed) for r in grid.done}
    expected = _expected(grid)
    total = sum(len(envs) for envs in expected.values()) * len(seeds)
    never: dict[tuple[str, ...], list[str]] = {}  # methods with no finished run, by envs
    partly: list[str] = []
    lost_cells = 0
    for method, envs in expected.items():
        by_seeds: dict[tuple[int, ...], list[str]] = {}
        for env in envs:
            lost = tuple(s for s in seeds if (env, method, s) not in found)
            if lost:
                by_seeds.setdefault(lost, []).append(env)
                lost_cells += len(lost)
        if not by_seeds:
            continue
        if list(by_seeds) == [tuple(seeds)] and len(by_seeds[tuple(seeds)]) == len(envs):
            never.setdefault(tuple(envs), []).append(method)
            continue
        n = sum(len(s) * len(e) for s, e in by_seeds.items())
        parts = [f"{', '.join(e)} × {seed_text(s)}" for s, e in by_seeds.items()]
        partly.append(f"- {method}: {'; '.join(parts)} ({_cells(n)})")
    if not lost_cells:
        lines = ["None: every expected cell has every seed."]
    else:
        n_envs = len({e for envs in expected.values() for e in envs})
        lines = [f"{lost_cells} of the grid's {total} cells have no finished run (each of its"
                 f" {len(expected)} methods on each of its {n_envs} environments, the ablations"
                 f" on {TABLE2_ENV} only; {seed_text(seeds)}):"]  # fmt: skip
        for envs, methods in never.items():
            where = envs[0] if len(envs) == 1 else f"{len(envs)} envs"
            lines.append(f"- no finished run at all: {', '.join(methods)} ({where} ×"
                         f" {seed_text(seeds)}, {_cells(len(envs) * len(seeds) * len(methods))})")
        lines += partly
    why: dict[tuple[str, str, str], list[Any]] = {}
    for r in grid.runs:
        if r.status == "ok":
            continue
        state = ("damaged final.json, skipped" if r.damaged is not None
                 else f"stopped, {r.status}" if r.final is not None
                 else "failed" if r.row.get("status") == "failed" else "unfinished")  # fmt: skip
        detail = escape((r.final or {}).get("message") or r.row.get("error") or "")
        why.setdefault((r.env, r.method, state), []).append((r.seed, detail))
    if why:
        lines += ["", "Runs without a result:"]
    for (env, method, state), items in why.items():
        details = {d for _, d in items if d}
        note = f" ({sorted(details)[0]})" if details else ""
        more = f" and {len(details) - 1} other message(s)" if len(details) > 1 else ""
        lines.append(f"- {env} / {method}: {state} on {seed_text([s for s, _ in items])}"
                     f"{note}{more}")
    if len(seeds) < 5:
        lines.append(f"- {len(seeds)} seed(s) per cell: the 95% intervals are wide; five or "
                     "more seeds per cell give usable ones")
    return lines


def references(grid: Grid) -> list[str]:
    """Expert and random reference returns per env (and split)."""
    lines = ["| Env | Split | Expert return | Random return | Layouts |", "|---|---|---|---|---|"]
    for env in sorted({r.env for r in grid.done}, key=env_order):
        ref = next((r.row["reference"] for r in grid.by_cell_env(env)
                    if isinstance(r.row.get("reference"), dict)
                    and "expert" in r.row["reference"]), None)  # fmt: skip
        if ref is None:
            lines.append(f"| {env} | – | unknown | unknown | – |")
            continue
        splits = [s for s in ("train", "test") if s in ref]
        if not splits:
            lines.append(f"| {env} | episodes | {fmt(ref['expert'])} | {fmt(ref['random'])} |"
                         " – |")  # fmt: skip
        for s in splits:
            lines.append(f"| {env} | {s} | {fmt(ref[s]['expert'])} | {fmt(ref[s]['random'])}"
                         f" | {ref[s]['layouts']} |")  # fmt: skip
    return lines


def all_runs(grid: Grid, csv_rows: list[dict[str, Any]]) -> list[str]:
    """Every (env, method) found, every evaluation in the CSV; the headline one in Markdown."""
    lines = ["| Env | Method | Seeds | P mean [95% CI] | AER mean [95% CI] | Success |"
             " Wall per seed (s) |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    order = {m: i for i, m in enumerate(grid.methods)}
    for env, method in sorted(grid.by_cell, key=lambda k: (env_order(k[0]), order[k[1]])):
        runs = grid.by_cell[(env, method)]
        evaluations = sorted({k for r in runs for k, v in (r.final or {}).items()
                              if isinstance(v, dict) and "performance" in v})  # fmt: skip
        for ev in evaluations:
            for metric in ("performance", "aer", "success_rate"):
                s = grid.stats(env, method, ev, metric)
                if s is not None:
                    csv_rows.append(stat_row("all", env, method, ev, metric, s))
        for kind in INTERACTION_KINDS:
            s = grid.interactions(env, method, kind)
            if s is not None:
                csv_rows.append(stat_row("all", env, method, "training",
                                          f"interactions/{kind}", s))  # fmt: skip
        ev = table_evaluation(env)
        walls = [r.row["wall_s"] for r in runs if r.row.get("wall_s") is not None]
        success = grid.stats(env, method, ev, "success_rate")
        perf, aer = grid.stats(env, method, ev, "performance"), grid.stats(env, method, ev, "aer")
        lines.append(
            f"| {env} | {method} | {len(runs)} | {ci_text(perf)} | {ci_text(aer)}"
            f" | {fmt(success.mean if success else None, 2)}"
            f" | {fmt(float(np.mean(walls)) if walls else None, 1)} |"
        )
    return lines


@dataclass(frozen=True)
class GridWall:
    """The grid's wall time as ``bench_log.jsonl`` tells it.

    Attributes:
        seconds: The sessions' summed wall time (``None``: no log).
        unfinished: Why the grid is not finished yet (its last session stopped before its end,
            with its count of cells), or ``None`` when it is, or when there is no log.
    """

    seconds: float | None
    unfinished: str | None = None


def _unfinished(sessions: list[dict[str, Any]], done: int) -> str | None:
    """Why the grid of ``sessions`` is unfinished: its last session did not reach its end."""
    if not sessions or sessions[-1].get("finished") is not False:
        return None
    cells = sessions[-1].get("cells")
    of = f" of {cells:,}" if isinstance(cells, int) else ""
    return f"its last `abco bench` session stopped before its end; {done:,}{of} cells done"


def wall(runs_dir: Path, grid: Grid, skipped: list[Skipped] | None = None
         ) -> tuple[GridWall, list[str]]:  # fmt: skip
    """The grid's wall time (``bench_log.jsonl``: sessions that ran cells) and its lines; a
    damaged line of the log goes to ``skipped`` (default: dropped)."""
    sessions = read_log(runs_dir, [] if skipped is None else skipped)
    ran = [s for s in sessions if s.get("ran") or s.get("failed")]
    wall_s = float(sum(s["wall_s"] for s in ran)) if sessions else None
    cell_wall = sum(r.row.get("wall_s") or 0.0 for r in grid.done)
    lines = [f"- Grid wall time: {fmt(wall_s, 1) if wall_s is not None else 'unknown'} s"
             f" ({fmt(wall_s / 3600 if wall_s is not None else None, 2)} h) over {len(ran)}"
             " `abco bench` session(s) that ran cells.",
             f"- Sum of the cells' own wall times: {cell_wall:.1f} s over {len(grid.done)} cells."]
    for s in ran:
        stopped = (", stopped before its end (its time up to its last finished cell)"
                   if s.get("finished") is False else "")  # fmt: skip
        lines.append(f"  - {escape(s.get('started'), 40)}: {s['wall_s']:.1f} s, backend"
                     f" {escape(s.get('backend'), 40)}, jobs {s.get('jobs')}, threads"
                     f" {s.get('threads')}, ran {s.get('ran')}, skipped {s.get('skipped')},"
                     f" failed {len(s.get('failed') or [])}{stopped}")  # fmt: skip
    # Cells copied in from another run folder (their row names it: ``reused_from``) ran in
    # no session of this log; their own time, spread over the sessions' jobs, is added.
    reused = [r for r in grid.done if r.row.get("reused_from")]
    if reused and wall_s is not None:
        jobs = max([int(s.get("jobs") or 1) for s in ran] or [1])
        own = float(sum(r.row.get("wall_s") or 0.0 for r in reused))
        wall_s += own / jobs
        lines.append(f"- {_cells(len(reused))} ran outside these sessions (`reused_from` in"
                     f" results.jsonl): {own:.1f} s of their own wall time, {own / jobs:.1f} s"
                     f" at {jobs} job(s) at once, counted in the grid's wall time"
                     f" ({wall_s:.1f} s, {wall_s / 3600:.2f} h).")  # fmt: skip
    done = len(grid.done) + len(grid.stopped)
    return GridWall(wall_s, _unfinished(sessions, done)), lines + _where_it_goes(grid, cell_wall)


def _where_it_goes(grid: Grid, cell_wall: float) -> list[str]:
    """Where the cells' own wall time goes: per env its share, and its three dearest methods."""
    by_env: dict[str, dict[str, float]] = {}
    counts: dict[str, int] = {}
    for r in grid.done:
        spent = by_env.setdefault(r.env, {})
        spent[r.method] = spent.get(r.method, 0.0) + float(r.row.get("wall_s") or 0.0)
        counts[r.env] = counts.get(r.env, 0) + 1
    if not by_env or cell_wall <= 0:
        return []
    lines = ["", "Where the cells' own wall time goes:", "",
             "| Env | Cells | Cell time (s) | Share | Dearest methods (s) |",
             "|---|---|---|---|---|"]
    for env in sorted(by_env, key=lambda e: -sum(by_env[e].values())):
        total = sum(by_env[env].values())
        dearest = sorted(by_env[env].items(), key=lambda kv: -kv[1])[:3]
        names = ", ".join(f"{LABELS.get(m, m)} {t:,.0f}" for m, t in dearest)
        lines.append(f"| {env} | {counts[env]} | {total:,.0f} | {total / cell_wall:.0%}"
                     f" | {names} |")
    return lines
