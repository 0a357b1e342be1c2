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
the host: each cell runs in a fresh process seeded by the trainer, with
``threads = cores // jobs`` decided once by the driver (``--threads`` to fix it, e.g. when a
cluster's nodes differ from the driver).
"""

from __future__ import annotations

import os
import socket
import sys
import time
import traceback
from collections.abc import Iterable, Sequence
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from abco_train.bench import backends
from abco_train.bench.cells import (
    CELL_FIELDS,
    Cell,
    cell_config,
    check_method_options,
    parse_layouts,
    parse_list,
    parse_seeds,
    plan,
)
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
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.run_folder import FINAL, config_differences, read_json
from abco_train.methods.registry import available, load_plugins, resolve_config

__all__ = [
    "Cell", "parse_seeds", "parse_list", "parse_layouts", "plan", "cell_config", "run_cell",
    "result_row",
    "read_results", "run_grid", "headline", "RESULTS_FILE", "BENCH_LOG",
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
        threads: Torch threads per cell (default ``max(1, cores // jobs)``).
        address: Ray cluster to join (``ray`` backend).
        quiet: No progress bar or per-cell lines.

    Returns:
        A summary: cells, ran, skipped, failed (keys), wall_s, and the path of the results.

    Raises:
        ConfigError: Unknown backend, env or method, a bad override, or finished cells of
            another config.
    """
    _check_backend_and_methods(backend, cells, plugins)
    check_method_options([c.method for c in cells], overrides, method_options)
    cores = backends.available_cores()
    local_jobs = max(1, jobs or cores)
    threads = int(threads or max(1, cores // local_jobs))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    configs = [cell_config(c, out, overrides, threads, method_options) for c in cells]
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
    _run_tasks(session, runner if tasks else (), [cells[i] for i in todo], tasks, quiet)
    summary = session.log(True)
    if not quiet:
        cell_s = sum(session.rows[cells[i].key].get("wall_s") or 0.0 for i in todo)
        print(f"{summary['ran']} cells run, {summary['skipped']} skipped,"
              f" {len(session.failed)} failed; wall {summary['wall_s']:.1f}s (cells"
              f" {cell_s:.1f}s); results: {summary['results']}")  # fmt: skip
    return summary


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
    """Whether each cell has its ``final.json``, every config checked before any cell starts.

    Raises:
        ConfigError: A bad setting, or a finished cell of another config.
    """
    for cfg in configs:
        resolve_config(RunConfig(**cfg))
    finished = [(Path(cfg["run_dir"]) / FINAL).exists() for cfg in configs]
    stale = [f"{c.key} ({', '.join(diff)})" for c, cfg, f in zip(cells, configs, finished)
             if f and (diff := _stale(cfg))]  # fmt: skip
    if stale:
        raise ConfigError(f"finished cells of another config under {out}: {'; '.join(stale)};"
                         " use another --out or delete them")  # fmt: skip
    return finished


def _stale(config: dict[str, Any]) -> list[str]:
    """Settings in which a finished cell's ``config.json`` differs from the requested config."""
    return config_differences(config["run_dir"], asdict(resolve_config(RunConfig(**config))))


def _results_so_far(out: Path, cells: Sequence[Cell], configs: list[dict[str, Any]],
                    finished: list[bool]) -> dict[str, dict[str, Any]]:  # fmt: skip
    """The rows of ``results.jsonl``, plus a row for each cell finished outside ``abco bench``."""
    rows = read_results(out)
    for cell, cfg, done in zip(cells, configs, finished):
        if done and rows.get(cell.key, {}).get("status") != "done":  # finished outside bench
            final = read_json(Path(cfg["run_dir"]) / FINAL)
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


def _run_tasks(session: _Session, runner: Iterable[tuple[int, Any]], cells: Sequence[Cell],
               tasks: list[dict[str, Any]], quiet: bool) -> None:  # fmt: skip
    """Record each task's outcome as it comes from the backend, with a progress bar."""
    from tqdm.auto import tqdm

    bar = tqdm(total=session.cells, initial=session.skipped, desc="abco bench", unit="cell",
               disable=quiet)  # fmt: skip
    for i, outcome in runner:
        if isinstance(outcome, BaseException):  # the worker died (e.g. out of memory)
            row = result_row(tasks[i], None, None, error=f"{type(outcome).__name__}: {outcome}")
        else:
            row = outcome
        session.record(cells[i], row)
        bar.update(1)
        if row["status"] != "done":
            why = row.get("error") or (row.get("final") or {}).get("message")
            bar.write(f"{cells[i].key}: FAILED, {row['status']} ({why})")
        elif not quiet:
            score = headline(row["final"])
            bar.write(f"{cells[i].key}: P={score['performance']:.3f} AER={score['aer']:.3f}"
                      f" in {row['wall_s']:.1f}s")  # fmt: skip
        session.log(False)
    bar.close()
