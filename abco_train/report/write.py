"""``abco report RUNS_DIR``: a benchmark of IfO methods, and the paper's tables re-measured.

Writes ``report.md``, ``results.csv`` (the same numbers, one row per statistic) and the plots
into ``--out`` (default ``RUNS_DIR/report``). Numbers come from every
``RUNS_DIR/{task or env}/{method}/seed{seed}/final.json`` (scores, P, AER, and the environment
interactions each run spent); wall times, reference returns and failures from
``results.jsonl`` and ``bench_log.jsonl`` (:mod:`abco_train.bench.results_log`).

Two tracks: records that carry a ``task`` (the benchmark track) come first, each task's
methods ranked by their headline score (:mod:`abco_train.report.headline`), then the IfO
methods' aggregates over tasks and their pairwise comparisons
(:mod:`abco_train.report.ranking`); records without one (the paper track) get the paper's
tables, with the paper's P. Every record's code version and training time:
:mod:`abco_train.report.provenance`.

The main table (Table 1 re-measured) holds every method found: the built-ins in the order of
:data:`ORDER`, then any other (a user's plugin) alphabetically. The pieces: runs and names
:mod:`~abco_train.report.runs`, per-cell statistics :mod:`~abco_train.report.stats`, aggregates
:mod:`~abco_train.report.aggregates`, tables :mod:`~abco_train.report.tables`, plots
:mod:`~abco_train.report.plots`; this module puts them together (:func:`write_report`).

Example:
    >>> table_evaluation("AbcoMaze5x5-v0", "test"), table_evaluation("CartPole-v1")
    ('test/paper', 'episodes')
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path
from typing import Any

from abco_data.format import files as file_ops
from abco_train.bench.records import RecordError, Skipped, check_config, escape, read_json
from abco_train.harness.run_folder import CONFIG, write_atomic
from abco_train.methods.base import INTERACTION_KINDS
from abco_train.report import aggregates as aggregate
from abco_train.report import budget_curves as curves
from abco_train.report import (
    generalisation,
    headline,
    headline_goals,
    health,
    provenance,
    ranking,
    tables,
)
from abco_train.report.headline_plots import TASKS_PNG, plot_task_scores
from abco_train.report.plots import plot_label_distributions, plot_performance
from abco_train.report.published import PAPER_TABLE2, published
from abco_train.report.runs import (
    CSV_FIELDS,
    GOALS,
    LABELS,
    MAZES,
    ORDER,
    TABLE1_ENVS,
    TABLE1_METHODS,
    TABLE2_ENV,
    TABLE2_METHODS,
    Grid,
    ReportError,
    Run,
    check_baseline,
    env_order,
    load_runs,
    method_order,
    table_evaluation,
)  # fmt: skip
from abco_train.report.summary import summary

__all__ = [
    "TABLE1_ENVS", "TABLE1_METHODS", "TABLE2_METHODS", "TABLE2_ENV", "ORDER", "LABELS",
    "GOALS", "CSV_FIELDS", "MAZES", "Run", "Grid", "load_runs", "write_report",
    "table_evaluation", "method_order", "env_order", "ReportError",
]  # fmt: skip

#: Most cells the grid found may span (envs × methods × seeds × numbers of layouts, the
#: built-ins' included): the tables go through every one of them.
MAX_SPAN = 10_000_000
#: The name of the staging folders (``.report.{pid}-{hex}.staging.abco-tmp``) in ``--out``.
STAGING = "report"

#: A plot of the report: its name in the returned files, its file (``None``: nothing to
#: plot) and its caption.
Plot = tuple[str, "Path | None", str]


def _settings(runs: list[Run], skipped: list[Skipped]) -> str:
    """The regime and preset of the grid's runs (from their config.json, each checked)."""
    seen: set[tuple[str, str]] = set()
    for r in runs:
        try:
            cfg = check_config(read_json(r.path / CONFIG))
        except FileNotFoundError:
            continue
        except RecordError as exc:
            skipped.append(Skipped(f"{r.where}/{CONFIG}", str(exc)))
            continue
        seen.add((str(cfg.get("regime", "default")), str(cfg.get("preset", "cpu"))))
    return "; ".join(f"regime {g}, preset {p}" for g, p in sorted(seen)) or "unknown"


def _intro(grid: Grid, skipped: list[Skipped]) -> list[str]:
    kinds = ", ".join(k.replace("_", "-") for k in INTERACTION_KINDS)
    return [
        f"{len(grid.done)} finished runs of {len(grid.methods)} method(s), seeds"
        f" {', '.join(map(str, grid.seeds)) or 'none'}; {len(grid.stopped)} run(s) stopped by"
        " their method's health check (e.g. an IDM at chance: no result, counted as '+k"
        " stopped' beside the seeds and summarised under Missing).",
        f"Settings: {_settings(grid.runs, skipped)}.",
        "P: the paper's performance measure, (R - random) / (expert - random) with the",
        "dataset's reference returns (Monteiro et al., IJCNN 2020), not the benchmark track's",
        "score. P and AER: mean over seeds with a 95% bootstrap CI, and the IQM. Classic control:",
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
                 budget_curves: str | Path | None = None, tuned_by: str | Path | None = None
                 ) -> dict[str, Path]:  # fmt: skip
    """Write ``report.md``, ``results.csv`` and the plots of the grid in ``runs_dir``.

    Args:
        runs_dir: The ``abco bench --out`` folder.
        out: Where to write (default ``runs_dir/report``).
        labels_env: Env of the IDM label-distribution plot (the paper's Figure 4: 5x5 maze).
        baseline: Reference method of the probability of improvement (default ``abco``; a
            name given must be a method of the grid).
        budget_curves: A grid of budget variants of the benchmark's tasks (tasks named
            ``{task}@x{multiple}``; :mod:`abco_train.report.budget_curves`): their curves,
            with the 1x points from ``runs_dir``, follow the benchmark track.
        tuned_by: An ``abco tune`` folder: the tuning effort of the grid's methods follows
            (:mod:`abco_train.report.tuning_effort`).

    Returns:
        The written files by name (``report``, ``csv``, and the plots that had data:
        ``headline_tasks``, ``headline_aggregates``, ``headline_profile``, ``budget_curves``,
        ``performance``, ``labels``, ``profile``, ``generalisation``).

    Every file is first written into a hidden staging folder in ``out``, then moved into
    place once all were written: a report that fails (a full or read-only disk) leaves the
    previous one as it was, with no file half-written.

    Raises:
        ReportError: ``runs_dir`` is not a folder, holds no run folders, or has no method
            ``baseline``; ``out`` is not a folder.
        InvalidTargetError: A file of the report is there as something else than a regular
            file (a folder, a device, a link): it is never replaced.
        OSError: A write failed (a full or read-only disk); nothing was replaced.
    """
    runs_dir = Path(runs_dir)
    skipped: list[Skipped] = []
    runs = _runs(runs_dir, skipped)
    baseline = check_baseline(baseline, Grid(runs), runs_dir)
    found = sorted({r.env for r in runs}, key=env_order)
    if labels_env not in found and labels_env not in TABLE1_ENVS:
        raise ReportError(f"unknown --labels-env {escape(labels_env, 80)!r}: not an env of"
                          f" {escape(runs_dir)}; envs found: {', '.join(found)}")  # fmt: skip
    out = _out_folder(runs_dir, out)
    stage = file_ops.temporary_name(out / STAGING, "staging")  # every file first here, then moved
    stage.mkdir()
    try:
        md, csv_rows, files = _compose(runs_dir, runs, skipped, stage, labels_env, baseline,
                                       budget_curves, tuned_by)  # fmt: skip
        _write(stage, md, csv_rows, files)
        return _publish(stage, out, files)
    finally:
        file_ops.remove_path(stage)


def _compose(runs_dir: Path, runs: list[Run], skipped: list[Skipped], out: Path,
             labels_env: str, baseline: str, budget_curves: str | Path | None = None,
             tuned_by: str | Path | None = None
             ) -> tuple[list[str], list[dict[str, Any]], dict[str, Path]]:  # fmt: skip
    """The report's Markdown lines, its CSV rows, and its plots (drawn into ``out``): the
    benchmark track (records with a task) first, then the paper track (records without)."""
    by_task, paper_runs = headline.split_tracks(runs)
    csv_rows: list[dict[str, Any]] = []
    timed, wall_lines = tables.wall(runs_dir, Grid(runs), skipped)
    current, why = provenance.current_code_version()
    md = ["## Code versions", "", *provenance.versions_section(runs, current, why)]
    plots: list[Plot] = []
    files: dict[str, Path] = {}
    if by_task:
        flags = provenance.flagged_counts(runs, current)
        lines, pngs = _benchmark(by_task, flags, skipped, out, csv_rows)
        track_runs = [r for task_runs in by_task.values() for r in task_runs]
        md += [*lines, "", *headline_goals.goals_section(headline.task_cells(by_task),
                                                         track_runs, csv_rows, timed.seconds,
                                                         timed.unfinished)]  # fmt: skip
        files.update(pngs)
    if budget_curves is not None:
        data = curves.curves(by_task, budget_curves, skipped)
        lines, png = curves.section(data, out, headline.HEADLINE_LABELS, csv_rows)
        md += ["", *lines]
        if png is not None:
            files["budget_curves"] = png
            md += [f"![Score against the interaction budget]({png.name})"]
    if tuned_by is not None:
        from abco_train.report import tuning_effort

        tuned = method_order({r.method for r in runs} - set(headline.REFERENCE_METHODS))
        md += ["", *tuning_effort.section(tuned_by, tuned)]
    if paper_runs:
        lines, plots, png = _paper_track(paper_runs, skipped, out, labels_env, baseline,
                                         timed.seconds, csv_rows)  # fmt: skip
        md += lines
        if png is not None:
            files["profile"] = png
    md += ["", "## Wall time", "", *wall_lines, "", *provenance.training_time(runs),
           "", "## Plots", ""]  # fmt: skip
    _plots(md, files, plots)
    # last, once every record the report reads has been read: what ran, and what was skipped
    md[:0] = [f"# IfO benchmark: {escape(runs_dir)}", "", "## Summary", "",
              *summary(runs, skipped), ""]  # fmt: skip
    return md, csv_rows, files


def _benchmark(by_task: dict[str, list[Run]], flags: dict[tuple[str, str], dict[str, int]],
               skipped: list[Skipped], out: Path, csv_rows: list[dict[str, Any]]
               ) -> tuple[list[str], dict[str, Path]]:  # fmt: skip
    """The benchmark track's sections: a table per task, the aggregates over tasks and the
    pairwise comparisons of the IfO methods (their plots drawn into ``out``, by name)."""
    cells = headline.task_cells(by_task)
    track = [r for runs in by_task.values() for r in runs]
    md = ["", "## Headline: the benchmark track, task by task", "",
          *headline.intro(len(cells), len(track), _settings(track, skipped))]  # fmt: skip
    md += ["", "Mean score over seeds, task by task (each task's table below gives its"
           " interval, success rate and interactions):", "", *headline.overview_table(cells)]
    tasks_png = plot_task_scores(cells, headline.HEADLINE_LABELS, out / TASKS_PNG)
    if tasks_png is not None:
        md += ["", f"![Headline score per task, 95% intervals]({tasks_png.name})"]
    for task, by_method in cells.items():
        flagged = {m: c for (t, m), c in flags.items() if t == task}
        md += ["", *headline.task_table(task, by_method, flagged, csv_rows)]
    ifo = [c for by_method in cells.values() for m, c in by_method.items()
           if m in headline.IFO_METHODS]  # fmt: skip
    scores: dict[str, dict[str, dict[int, float]]] = {}
    for c in ifo:
        if c.scored and c.values:
            scores.setdefault(c.method, {})[c.task] = c.values
    older = sum(c.older if c.scored else len(c.values) for c in ifo)
    lines, pngs = ranking.section(scores, list(cells), out, headline.HEADLINE_LABELS, csv_rows,
                                  older)  # fmt: skip
    md += ["", "### Health checks", "", *(health.flagged_lines(track) or ["No check fired."])]
    return [*md, "", *lines], pngs | ({"headline_tasks": tasks_png} if tasks_png else {})


def _paper_track(runs: list[Run], skipped: list[Skipped], out: Path, labels_env: str,
                 baseline: str, wall: float | None, csv_rows: list[dict[str, Any]]
                 ) -> tuple[list[str], list[Plot], Path | None]:  # fmt: skip
    """The paper track's sections (records without a task), its plots, and its aggregates'
    profile plot (``None``: not drawn)."""
    grid = Grid([r for r in runs if r.layouts is None])  # the paper's tables: standard data
    every = Grid(runs)
    label = {m: LABELS.get(m, m) for m in every.methods + grid.main_methods}
    gen_lines, gen_png = generalisation.section(runs, csv_rows, out, label)
    plots: list[Plot] = [("generalisation", gen_png, generalisation.CAPTION)]
    head = ["", "## The paper track: records without a task (the paper's P)", ""]
    if not grid.runs:  # procedural-data runs only: the generalisation section
        md = [*head, *_intro(every, skipped), "", "## Generalisation", "", *gen_lines]
        return md, plots, None
    envs = [e for e in TABLE1_ENVS if any(grid.has(e, m) for m in grid.main_methods)]
    agg_lines, agg_rows, profile_png = aggregate.section(
        grid.scores(grid.main_methods, envs), envs, baseline, out, label,
        evaluation="train/paper (mazes), episodes")  # fmt: skip
    md = [*head, *_intro(grid, skipped),
          *_paper_sections(grid, wall, agg_lines, gen_lines, label, csv_rows, len(envs))]
    csv_rows += agg_rows  # the aggregates' rows last
    return md, _paper_plots(grid, out, labels_env) + plots, profile_png


def _out_folder(runs_dir: Path, out: str | Path | None) -> Path:
    """The report's folder (made if needed), its previous files checked: each one the report
    replaces must be a regular file.

    Raises:
        ReportError: ``out`` is not a folder.
        InvalidTargetError: A file the report writes is there as something else (a folder,
            a device, a link).
    """
    out = Path(out) if out is not None else runs_dir / "report"
    if out.exists() and not out.is_dir():
        raise ReportError(f"--out {escape(out)} is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    file_ops.remove_stale_temporaries(out, STAGING)  # the staging folders of killed reports
    for name in ("report.md", "results.csv"):
        file_ops.check_target(out / name)
    return out


def _publish(stage: Path, out: Path, files: dict[str, Path]) -> dict[str, Path]:
    """Move every file of ``stage`` into ``out`` (once all were written: a report that fails
    leaves the previous one as it was); the files by name, in ``out``."""
    names = sorted(p.name for p in stage.iterdir())
    for name in names:
        file_ops.check_target(out / name)
    for name in names:
        os.replace(stage / name, out / name)
    return {key: out / path.name for key, path in files.items()}


def _runs(runs_dir: Path, skipped: list[Skipped]) -> list[Run]:
    """The runs of ``runs_dir`` (the records skipped go to ``skipped``).

    Raises:
        ReportError: ``runs_dir`` is not a folder or holds no run folders.
    """
    if not runs_dir.is_dir():
        raise ReportError(f"no such folder {escape(runs_dir)}")
    runs = load_runs(runs_dir, skipped)
    envs, methods = {r.env for r in runs} | set(TABLE1_ENVS), {r.method for r in runs} | set(ORDER)
    sizes = (len(envs), len(methods), len({r.seed for r in runs}), len({r.layouts for r in runs}))
    if sizes[0] * sizes[1] * sizes[2] * sizes[3] > MAX_SPAN:
        raise ReportError(f"{escape(runs_dir)}: its {len(runs):,} run folders span more cells than"
                          f" a report covers ({MAX_SPAN:,}): {sizes[0]:,} envs × {sizes[1]:,}"
                          f" methods × {sizes[2]:,} seeds × {sizes[3]:,} numbers of layouts;"
                          " report on one grid at a time")  # fmt: skip
    if not runs:
        why = f" ({len(skipped)} skipped, the first: {skipped[0]})" if skipped else ""
        raise ReportError(f"{escape(runs_dir)} holds no run folders"
                          f" ({{env}}/{{method}}/seed{{n}}){why}; is it an `abco bench --out`"
                          " folder?")  # fmt: skip
    return runs


def _paper_sections(grid: Grid, wall: float | None, agg_lines: list[str],
                    gen_lines: list[str], label: dict[str, str],
                    csv_rows: list[dict[str, Any]], n_envs: int) -> list[str]:  # fmt: skip
    """The sections of a grid with standard-data runs, from the goals to the reference
    returns: the paper's tables, the aggregates (``agg_lines``, over ``n_envs`` environments),
    the generalisation section (``gen_lines``), what is missing. Their CSV rows are appended."""
    main = grid.main_methods
    t1 = [(e, m, label[m], published(m, e)) for e in TABLE1_ENVS for m in main
          if grid.has(e, m)]  # fmt: skip
    t1_test = [(e, m, label[m], None) for e in MAZES for m in main if grid.has(e, m)]
    t2 = [(TABLE2_ENV, m, lab, PAPER_TABLE2.get(m)) for m, lab in TABLE2_METHODS.items()
          if grid.has(TABLE2_ENV, m)]  # fmt: skip
    t2_test = [(e, m, lab, None) for e, m, lab, _ in t2]
    means = {e: {m: s.mean for m in main
                 if (s := grid.stats(e, m, table_evaluation(e), "performance"))}
             for e in TABLE1_ENVS}  # fmt: skip
    empty = ["No finished or stopped run of these cells."]
    return [
        "", "## Goals (mean over seeds)", "", *tables.goals(grid, wall),
        "", "## Table 1 re-measured: every method, train split (the paper's protocol)", "",
        *(tables.table(grid, t1, "train", csv_rows, "table1", counts=True) if t1 else empty),
        "", f"## Aggregates: {n_envs} of the {len(TABLE1_ENVS)} environments of Table 1", "",
        *agg_lines, "", "## Which environments separate methods", "",
        *aggregate.separation(means, TABLE1_ENVS, label),
        "", "## Table 1, mazes on the held-out test split", "",
        *(tables.table(grid, t1_test, "test", csv_rows, "table1-test") if t1_test else empty),
        "", "## Generalisation: held-out and fresh layouts", "", *gen_lines,
        "", "## Table 2: ablation on the 5x5 maze, train split", "",
        *(tables.table(grid, t2, "train", csv_rows, "table2") if t2 else empty),
        "", "Table 2's BCO row is BCO(α) (the paper's Table 2 BCO repeats Table 1's).",
        "", "### Table 2 on the test split", "",
        *(tables.table(grid, t2_test, "test", csv_rows, "table2-test") if t2 else empty),
        "", "## Missing, unfinished, failed or stopped cells", "", *tables.missing(grid),
        "", "## Health checks (the runs went on to their end)", "",
        *(health.flagged_lines(grid.runs) or ["No check fired."]),
        "", "## Every (env, method) found: success rate and wall time", "",
        "Train split; every evaluation of every cell is in the CSV (`table` = `all`).", "",
        *tables.all_runs(grid, csv_rows),
        "", "## Reference returns (P = (R - random) / (expert - random))", "",
        "Mazes normalise per layout; the means over each split's layouts are shown.", "",
        *tables.references(grid),
    ]  # fmt: skip


def _paper_plots(grid: Grid, out: Path, labels_env: str) -> list[Plot]:
    """The plots of the standard-data runs: P per iteration, the IDM's label distribution."""
    perf_png = plot_performance(grid.by_cell, out / "performance_per_iteration.png", env_order)
    labels_png = plot_label_distributions(grid.by_cell, labels_env, ("bco-alpha", "abco"),
                                          out / "idm_label_distribution.png")  # fmt: skip
    return [
        ("performance", perf_png, "P per iteration (band: min..max across seeds)"),
        ("labels", labels_png, f"IDM label distribution, BCO(α) vs ABCO on {escape(labels_env)}"),
    ]  # fmt: skip


def _plots(md: list[str], files: dict[str, Path], plots: list[Plot]) -> None:
    """Each plot's Markdown image (or a line saying it had no runs) and its file entry."""
    for name, png, caption in plots:
        if png is None:
            md.append(f"- {caption}: no runs to plot.")
        else:
            files[name] = png
            md.append(f"![{caption}]({png.name})")


def _write(out: Path, md: list[str], csv_rows: list[dict[str, Any]],
           files: dict[str, Path]) -> None:  # fmt: skip
    """Write ``report.md`` and ``results.csv`` into ``out``; add them to ``files``."""
    table = io.StringIO(newline="")
    writer: csv.DictWriter[str] = csv.DictWriter(table, fieldnames=CSV_FIELDS)
    writer.writeheader()
    writer.writerows({k: escape(v, 10**6) if isinstance(v, str) else v for k, v in r.items()}
                     for r in csv_rows)  # fmt: skip
    files["report"] = write_atomic(out / "report.md", "\n".join(md) + "\n")
    files["csv"] = write_atomic(out / "results.csv", lambda p: p.write_bytes(
        table.getvalue().encode("utf-8")))  # fmt: skip
