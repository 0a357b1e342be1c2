"""The (env, method, seed) grid of ``abco bench``, each cell an independent training run.

Every cell is :func:`abco_train.harness.loop.train` with the trainer's defaults (plus the overrides
given to the whole grid) in its own run folder ``OUT/{env}/{method}/seed{seed}``; a grid over
numbers of training layouts (``abco bench --layouts 100,1000``, the generalisation protocol)
has one more level, ``OUT/{env}/{method}/layouts{K}/seed{seed}``:

* a cell whose ``final.json`` exists is skipped, so re-running an interrupted benchmark
  resumes it; a cell with a ``checkpoint.pt`` but no ``final.json`` resumes through the
  trainer's own resuming;
* finished cells are collected, one JSON line per cell, in ``OUT/results.jsonl`` (rewritten
  atomically after every cell; the latest row of a cell wins), and every invocation keeps
  its line in ``OUT/bench_log.jsonl`` (written at its start, rewritten after every cell and
  at its end, so a killed session still leaves its time up to its last finished cell).

The rooms of ``abco bench``: the cells and the plan are :mod:`abco_train.bench.cells`; the two
files :mod:`abco_train.bench.results_log`; the backends that run the cells (local processes,
Ray) :mod:`abco_train.bench.backends`; this module runs a grid (:func:`run_grid`) and
re-exports the public names of the first two, so that ``abco_train.bench.grid`` is the one
import a user of the grid needs. The command line is in :mod:`abco_train.cli`. A cell's
numbers depend only on its config (seed and torch threads included), never on the backend or
the host: each cell runs in a fresh process seeded by the trainer, with the trainer's one torch
thread unless ``--threads`` gives another number.

One session writes a grid's folder at a time: :func:`run_grid` holds the folder's lock
(:mod:`abco_train.bench.lock`) from its first write to its last, and a second session is
refused at once. Every record it reuses is checked first (:mod:`abco_train.bench.records`): a
damaged ``results.jsonl`` row or a finished cell's damaged ``final.json`` stops the grid
with one line naming the file, before any cell runs.
"""

from __future__ import annotations

import os
import socket
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from abco_train.bench import backends
from abco_train.bench.cells import (
    CELL_FIELDS,
    Cell,
    Tuned,
    cell_config,
    check_method_options,
    parse_layouts,
    parse_list,
    parse_seeds,
    plan,
    plan_track,
)
from abco_train.bench.lock import grid_lock
from abco_train.bench.records import RecordError, check_config, check_final, escape, read_json
from abco_train.bench.results_log import (
    BENCH_LOG,
    RESULTS_FILE,
    headline,
    log_size,
    read_results,
    result_row,
    write_log_line,
    write_results,
)
from abco_train.bench.tasks import Track, load_track
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.run_folder import CONFIG, FINAL, config_differences
from abco_train.methods.registry import available, load_plugins, resolve_config

__all__ = [
    "Cell", "parse_seeds", "parse_list", "parse_layouts", "plan", "plan_track", "load_track",
    "Track", "cell_config", "run_cell",
    "result_row",
    "read_results", "run_grid", "failed_text", "headline", "RESULTS_FILE", "BENCH_LOG",
    "CELL_FIELDS",
]  # fmt: skip


def run_cell(config: dict[str, Any], plugins: Sequence[str] = ()) -> dict[str, Any]:
    """Train one cell (in whatever process or Ray worker runs it) and return its row.

    Never raises: a failure comes back as a row with ``status: "failed"`` and the traceback.
    """
    t0 = time.perf_counter()
    host = {"host": socket.gethostname(), "pid": os.getpid()}
    try:
        load_plugins(plugins)
        from abco_train.harness.loop import train

        final = train(RunConfig(**config))
    except Exception as exc:
        row = result_row(config, None, time.perf_counter() - t0, **host)
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc()
        return row
    return result_row(config, final, time.perf_counter() - t0, **host)


def run_grid(
    cells: Sequence[Cell],
    out: str | os.PathLike[str],
    *,
    overrides: dict[str, Any] | None = None,
    method_options: dict[str, Any] | None = None,
    plugins: Sequence[str] = (),
    backend: str = "local",
    jobs: int | None = None,
    threads: int | None = None,
    address: str | None = None,
    quiet: bool = False,
    track: Track | None = None,
    tuned: Tuned | None = None,
) -> dict[str, Any]:
    """Run the unfinished cells of a grid and collect every cell into ``results.jsonl``.

    Args:
        cells: The grid (:func:`plan`).
        out: The grid's folder.
        overrides: Trainer settings for every cell (``RunConfig`` fields, or a method's
            options, which go to the cells whose method has them).
        method_options: Method options, for every cell whose method has them.
        plugins: Modules or ``.py`` files to import first (in every worker too).
        backend: ``local`` (processes) or ``ray``.
        jobs: Cells at once (local default: the cores; ray default: as the cluster allows).
        threads: Torch threads per cell (default: the cores divided by ``jobs``, at least 1;
            with the default ``jobs``, one).
        address: Ray cluster to join (``ray`` backend).
        quiet: No progress bar or per-cell lines.
        track: The track of a grid of task cells (:func:`~abco_train.bench.cells.plan_track`).
        tuned: Settings chosen per method and task family (``abco tune``'s choices), under
            ``overrides`` and ``method_options``.

    Returns:
        A summary: cells, ran, skipped, failed (keys), wall_s, the path of the results (the
        session's line of the bench log), and failures (why each failed cell failed, one
        line each; :func:`failed_text` says it in one line).

    Raises:
        ConfigError: No cell, an unknown backend, env or method, a bad override, or finished
            cells of another config.
        RecordError: A damaged record the grid would reuse (``results.jsonl``, a finished
            cell's ``final.json`` or ``config.json``).
        GridInUseError: Another session holds the grid's folder.
    """
    if not cells:
        raise ConfigError("the grid has no cell (no env, method or seed given)")
    _check_backend_and_methods(backend, cells, plugins)
    check_method_options([c.method for c in cells], overrides, method_options)
    _check_tuned(cells, tuned)
    cores = backends.available_cores()
    local_jobs = max(1, jobs or cores)
    # jobs x threads fill the cores: one thread per cell at one cell per core (threads spin-wait
    # on each other when cores are shared), the spare cores' threads when fewer cells run.
    threads = int(threads or max(1, cores // local_jobs))
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {escape(out)} is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    configs = [cell_config(c, out, overrides, threads, method_options, track, tuned) for c in cells]
    with grid_lock(out):
        finished = _finished_cells(cells, configs, out)
        rows = _results_so_far(out, cells, configs, finished)
        todo = [i for i, done in enumerate(finished) if not done]
        write_results(out, rows)
        session = _Session(out, rows, backend, jobs or local_jobs, threads, len(cells),
                           len(cells) - len(todo))  # fmt: skip
        session.log(False)
        tasks = [configs[i] for i in todo]
        runner = (
            backends.run_local(run_cell, tasks, plugins, min(local_jobs, max(len(tasks), 1)))
            if backend == "local" else backends.run_ray(run_cell, tasks, plugins, jobs, address)
        )  # fmt: skip
        try:
            _run_tasks(session, runner if tasks else (), [cells[i] for i in todo], tasks, quiet)
        finally:  # a stopped grid stops its backend before the lock is released
            getattr(runner, "close", lambda: None)()
        summary = {**session.log(True), "failures": session.failures}
    if not quiet:
        cell_s = sum(session.rows[cells[i].key].get("wall_s") or 0.0 for i in todo)
        print(f"{summary['ran']} cells run, {summary['skipped']} skipped,"
              f" {len(session.failed)} failed; wall {summary['wall_s']:.1f}s (cells"
              f" {cell_s:.1f}s); results: {escape(summary['results'])}")  # fmt: skip
    return summary


def _check_tuned(cells: Sequence[Cell], tuned: Tuned | None) -> None:
    """Raise :class:`ConfigError` for a chosen option a method of the grid does not have."""
    methods = {c.method for c in cells}
    for (method, _), (_, chosen) in (tuned or {}).items():
        if method in methods:
            check_method_options([method], None, dict(chosen))


def _check_backend_and_methods(backend: str, cells: Sequence[Cell], plugins: Sequence[str]
                               ) -> None:  # fmt: skip
    """Raise :class:`ConfigError` for an unknown backend, or a method no plugin registers."""
    if backend not in backends.BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; expected one of {backends.BACKENDS}")
    load_plugins(plugins)
    unknown = sorted({c.method for c in cells} - set(available()))
    if unknown:
        raise ConfigError(f"unknown method(s) {', '.join(unknown)}; registered: "
                         f"{', '.join(available())} (a plugin may register more)")  # fmt: skip


def _finished_cells(cells: Sequence[Cell], configs: list[dict[str, Any]], out: Path
                    ) -> list[bool]:  # fmt: skip
    """Whether each cell has its ``final.json``, every config and every finished cell's
    records checked before any cell starts.

    Raises:
        ConfigError: A bad setting, or a finished cell of another config.
        RecordError: A finished cell's ``final.json`` or ``config.json`` is damaged or not
            that cell's (never reused: the message names the file).
    """
    for cfg in configs:
        resolve_config(RunConfig(**cfg))
    finished = [_is_file(Path(cfg["run_dir"]) / FINAL) for cfg in configs]
    for cell, cfg, done in zip(cells, configs, finished):
        if done:
            _finished_record(cell, Path(cfg["run_dir"]))
    stale = [f"{c.key} ({', '.join(diff)})" for c, cfg, f in zip(cells, configs, finished)
             if f and (diff := _stale(cfg))]  # fmt: skip
    if stale:
        raise ConfigError(f"finished cells of another config under {escape(out)}:"
                          f" {escape('; '.join(stale), 600)}; use another --out or delete"
                          " them")  # fmt: skip
    return finished


def _is_file(path: Path) -> bool:
    """``path`` exists (as anything: a folder or a device there is refused when it is read)."""
    return os.path.lexists(path)


def _finished_record(cell: Cell, run_dir: Path) -> dict[str, Any]:
    """The checked ``final.json`` of a finished cell (its ``config.json`` checked too).

    Raises:
        RecordError: Either file is damaged, or the record is not this cell's.
    """
    final = _checked(run_dir / FINAL, lambda x: check_final(x, _cell_id(cell)))
    if _is_file(run_dir / CONFIG):
        _checked(run_dir / CONFIG, check_config)
    return final


def _checked(path: Path, check: Callable[[Any], dict[str, Any]]) -> dict[str, Any]:
    """The record at ``path``, checked by ``check``.

    Raises:
        RecordError: It cannot be read or fails the check (the message names the file).
    """
    try:
        return check(read_json(path))
    except (FileNotFoundError, RecordError) as exc:
        why = "missing or a broken link" if isinstance(exc, FileNotFoundError) else str(exc)
        raise RecordError(f"{escape(path)} is not a finished run's record ({why}); the grid"
                          " does not reuse it: delete it to run the cell again") from None


def _cell_id(cell: Cell) -> tuple[str, str, int, int | None]:
    return cell.ident


def _stale(config: dict[str, Any]) -> list[str]:
    """Settings in which a finished cell's ``config.json`` differs from the requested config."""
    return config_differences(config["run_dir"], asdict(resolve_config(RunConfig(**config))))


def _results_so_far(out: Path, cells: Sequence[Cell], configs: list[dict[str, Any]],
                    finished: list[bool]) -> dict[str, dict[str, Any]]:  # fmt: skip
    """The rows of ``results.jsonl``, plus a row for each cell finished outside ``abco bench``."""
    rows = read_results(out)
    for cell, cfg, done in zip(cells, configs, finished):
        if done and rows.get(cell.key, {}).get("status") != "done":  # finished outside bench
            final = _finished_record(cell, Path(cfg["run_dir"]))
            rows[cell.key] = result_row(cfg, final, None, cached_only=True)
    return rows


class _Session:
    """This ``abco bench`` invocation: the grid's rows so far, and its line in the bench log.

    The line is written at the start and rewritten after every cell (:meth:`log`), so a
    session killed mid-grid still leaves its time up to its last finished cell.
    """

    def __init__(self, out: Path, rows: dict[str, dict[str, Any]], backend: str, jobs: int,
                 threads: int, cells: int, skipped: int) -> None:  # fmt: skip
        self.out, self.rows, self.backend = out, rows, backend
        self.jobs, self.threads, self.cells, self.skipped = jobs, threads, cells, skipped
        self.t0 = time.perf_counter()
        self.started = datetime.now(timezone.utc).isoformat(timespec="seconds")
        self.ran = 0
        self.failed: list[str] = []
        #: Why each failed cell failed (one escaped line each; not in the log).
        self.failures: dict[str, str] = {}
        self.line = log_size(out)

    def record(self, cell: Cell, row: dict[str, Any]) -> None:
        """Keep a cell's row (in ``results.jsonl`` at once) and count it."""
        row["backend"] = self.backend
        self.rows[cell.key] = row
        write_results(self.out, self.rows)
        self.ran += int(row["status"] == "done")
        if row["status"] != "done":
            self.failed.append(cell.key)

    def log(self, finished: bool) -> dict[str, Any]:
        """Write the session's line of the bench log, and return it."""
        summary = {
            "started": self.started, "wall_s": time.perf_counter() - self.t0,
            "backend": self.backend, "jobs": self.jobs, "threads": self.threads,
            "cells": self.cells, "ran": self.ran, "skipped": self.skipped,
            "failed": self.failed, "finished": finished, "argv": sys.argv[1:],
            "results": str(self.out / RESULTS_FILE),
        }  # fmt: skip
        write_log_line(self.out, self.line, summary)
        return summary


def _failure(row: dict[str, Any]) -> str:
    """Why a cell failed, on one line (its error, or its method's message)."""
    return escape(row.get("error") or (row.get("final") or {}).get("message") or "no reason",
                  2000)  # fmt: skip


def failed_text(summary: dict[str, Any]) -> str:
    """One line on the failed cells of a session (:func:`run_grid`'s summary): how many, the
    first with its reason, where the rest are.

    Example:
        >>> failed_text({"cells": 4, "failed": ["a/b/seed0"], "failures": {"a/b/seed0": "boom"},
        ...              "results": "out/results.jsonl"})
        "1 of 4 cells failed: a/b/seed0 (boom); every cell's error is in out/results.jsonl"
    """
    failed = summary.get("failed") or []
    if not failed:
        return "no cell failed"
    first = failed[0]
    why = summary.get("failures", {}).get(first, "")
    more = f", and {len(failed) - 1} more" if len(failed) > 1 else ""
    return (f"{len(failed)} of {summary.get('cells')} cells failed: {escape(first)}"
            + (f" ({why})" if why else "") + f"{more}; every cell's error is in"
            f" {escape(summary.get('results'))}")


def _run_tasks(session: _Session, runner: Iterable[tuple[int, Any]], cells: Sequence[Cell],
               tasks: list[dict[str, Any]], quiet: bool) -> None:  # fmt: skip
    """Record each task's outcome as it comes from the backend, with a progress bar."""
    from abco_data.progress import progress_bar

    bar = progress_bar(total=session.cells, initial=session.skipped, desc="abco bench", unit="cell",
               disable=quiet)  # fmt: skip
    for i, outcome in runner:
        if isinstance(outcome, BaseException):  # the worker died (e.g. out of memory)
            row = result_row(tasks[i], None, None, error=f"{type(outcome).__name__}: {outcome}")
        else:
            row = outcome
        session.record(cells[i], row)
        bar.update(1)
        if row["status"] != "done":
            why = _failure(row)
            session.failures[cells[i].key] = why
            bar.write(f"{escape(cells[i].key)}: FAILED, {escape(row['status'])} ({why})")
        elif not quiet:
            block = headline(row["final"])
            shown = "" if block.get("score") is None else f"score={block['score']:.3f} "
            bar.write(f"{escape(cells[i].key)}: {shown}P={block['performance']:.3f} "
                      f"AER={block['aer']:.3f} in {row['wall_s']:.1f}s")  # fmt: skip
        session.log(False)
    bar.close()
