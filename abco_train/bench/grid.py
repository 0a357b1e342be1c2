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

The backends that run the cells (local processes, Ray) are in :mod:`abco_train.bench.backends`;
the command line is in :mod:`abco_train.cli`. A cell's numbers depend only on its config
(seed and torch threads included), never on the backend or the host: each cell runs in a
fresh process seeded by the trainer, with ``threads = cores // jobs`` decided once by the
driver (``--threads`` to fix it, e.g. when a cluster's nodes differ from the driver).

Example:
    >>> parse_seeds("0-2,7")
    [0, 1, 2, 7]
    >>> [c.key for c in plan(["CartPole-v1"], ["bc", "abco"], [0])]
    ['CartPole-v1/bc/seed0', 'CartPole-v1/abco/seed0']
    >>> [c.key for c in plan(["AbcoMaze5x5-v0"], ["bc"], [0], layouts=[100, 1000])]
    ['AbcoMaze5x5-v0/bc/layouts100/seed0', 'AbcoMaze5x5-v0/bc/layouts1000/seed0']
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
import traceback
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from abco_train.bench import backends
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.run_folder import FINAL, config_differences, read_json, write_atomic
from abco_train.harness.training_data import KINDS, resolve_dataset
from abco_train.methods.registry import available, load_plugins, resolve_config

__all__ = [
    "Cell", "parse_seeds", "parse_list", "parse_layouts", "plan", "cell_config", "run_cell",
    "result_row",
    "read_results", "run_grid", "headline", "RESULTS_FILE", "BENCH_LOG",
    "CELL_FIELDS",
]  # fmt: skip

RESULTS_FILE = "results.jsonl"
BENCH_LOG = "bench_log.jsonl"
#: Config fields the grid sets per cell (never trainer overrides).
CELL_FIELDS = ("env", "method", "seed", "layouts", "run_dir", "quiet", "threads",
               "method_options")  # fmt: skip


@dataclass(frozen=True)
class Cell:
    """One training run of the grid."""

    env: str
    method: str
    seed: int
    layouts: int | None = None

    @property
    def key(self) -> str:
        """``env/method/seed{seed}`` (``env/method/layouts{K}/seed{seed}`` for a cell that
        trains on the first K procedural layouts): its run folder under the grid's folder."""
        return str(self.run_dir(Path())).replace(os.sep, "/")

    def run_dir(self, out: str | os.PathLike[str]) -> Path:
        """The cell's run folder under ``out``."""
        folder = Path(out) / self.env / self.method
        if self.layouts is not None:
            folder = folder / f"layouts{self.layouts}"
        return folder / f"seed{self.seed}"


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``"0-4"``, ``"0,3,5"`` or mixes like ``"0-2,7"`` (order kept, no repeats).

    Raises:
        ConfigError: A malformed part or an empty range.
    """
    seeds: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            first, last = (int(lo), int(hi)) if sep else (int(part), int(part))
        except ValueError:
            raise ConfigError(f"bad seed range {part!r}; expected e.g. 0-4 or 0,2,5") from None
        if last < first or first < 0:
            raise ConfigError(f"empty or negative seed range {part!r}")
        seeds += [s for s in range(first, last + 1) if s not in seeds]
    if not seeds:
        raise ConfigError("no seeds given")
    return seeds


def parse_layouts(text: str) -> list[int]:
    """Numbers of training layouts from ``"100,1000,10000"`` (``10k`` and ``1,000``-style
    thousands are not accepted: plain integers, comma-separated; order kept, no repeats).

    Raises:
        ConfigError: Not a positive integer.
    """
    out: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        if not part.isdigit() or int(part) < 1:
            raise ConfigError(f"bad --layouts value {part!r}; expected positive integers such as"
                              " 100,1000,10000")  # fmt: skip
        if int(part) not in out:
            out.append(int(part))
    if not out:
        raise ConfigError("no --layouts given")
    return out


def parse_list(text: str) -> list[str]:
    """Comma-separated names, blanks dropped, order kept, no repeats."""
    out: list[str] = []
    for name in (p.strip() for p in text.split(",")):
        if name and name not in out:
            out.append(name)
    return out


def plan(envs: Sequence[str], methods: Sequence[str], seeds: Sequence[int],
         layouts: Sequence[int | None] = (None,)) -> list[Cell]:  # fmt: skip
    """Every (env, method, layouts, seed) cell, env-major; ``layouts``: numbers of training
    layouts (``None``: the standard datasets)."""
    return [Cell(e, m, int(s), None if k is None else int(k))
            for e in envs for m in methods for k in layouts for s in seeds]  # fmt: skip


def cell_config(
    cell: Cell,
    out: str | os.PathLike[str],
    overrides: dict[str, Any] | None = None,
    threads: int = 1,
    method_options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The keyword arguments of the cell's :class:`abco_train.config.run.RunConfig`.

    Args:
        cell: The cell.
        out: The grid's folder.
        overrides: Trainer settings applied to every cell (``None`` values are dropped).
        threads: Torch threads of the cell.
        method_options: ``RunConfig.method_options`` of every cell.

    Raises:
        ConfigError: An override of a per-cell field (env, method, seed, run_dir, ...).
    """
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    clash = sorted(set(overrides) & set(CELL_FIELDS))
    if clash:
        raise ConfigError(f"the grid sets {', '.join(clash)} per cell; not an override")
    return {
        **overrides, "env": cell.env, "method": cell.method, "seed": cell.seed,
        **({"layouts": cell.layouts} if cell.layouts is not None else {}),
        "run_dir": str(cell.run_dir(out)), "quiet": True, "threads": int(threads),
        "method_options": dict(method_options or {}),
    }  # fmt: skip


def _references(config: dict[str, Any], cached_only: bool = False) -> dict[str, Any]:
    """Expert/random reference returns (per split for mazes) and the expert's true actions."""
    import numpy as np

    try:
        ds = resolve_dataset(config.get("expert_data"), config["env"], KINDS["expert"],
                             cache_dir=config.get("cache_dir"), cached_only=cached_only)
    except Exception as exc:  # the references are informative only
        return {"error": f"{type(exc).__name__}: {exc}"}
    ref = ds.reference
    out: dict[str, Any] = {"expert": float(ref.expert_mean), "random": float(ref.random_mean)}
    if ref.layout_splits is not None:
        splits = np.asarray(ref.layout_splits)
        for split in ("train", "test"):
            mask = splits == split
            if mask.any():
                out[split] = {
                    "expert": float(np.asarray(ref.expert_per_layout)[mask].mean()),
                    "random": float(np.asarray(ref.random_per_layout)[mask].mean()),
                    "layouts": int(mask.sum()),
                }
    actions = np.asarray(ds.actions_of_transitions(idm_eval=True), dtype=np.int64)
    n = int(ds.action_space.n)
    out["expert_actions"] = (np.bincount(actions, minlength=n) / max(len(actions), 1)).tolist()
    return out


def result_row(config: dict[str, Any], final: dict[str, Any] | None, wall_s: float | None,
               cached_only: bool = False, **extra: Any) -> dict[str, Any]:  # fmt: skip
    """One line of ``results.jsonl``: the cell, its final evaluation, references, wall time.

    ``cached_only``: read the references only from datasets already on disk (never fetch).
    """
    return {
        "env": config["env"], "method": config["method"], "seed": int(config["seed"]),
        **({"layouts": config["layouts"]} if config.get("layouts") is not None else {}),
        "run_dir": str(config["run_dir"]), "status": _status(final),
        "final": final, "wall_s": wall_s, "threads": config.get("threads"),
        "reference": _references(config, cached_only) if _status(final) == "done" else None,
        **extra,
    }  # fmt: skip


def _status(final: dict[str, Any] | None) -> str:
    """``done``; ``failed`` (an error); or the method's failure status (``idm_at_chance``)."""
    if final is None:
        return "failed"
    status = final.get("status", "ok")
    return "done" if status == "ok" else status


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


def read_results(out: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """The rows of ``out/results.jsonl`` by cell key (the latest row of a cell wins)."""
    path = Path(out) / RESULTS_FILE
    rows: dict[str, dict[str, Any]] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                cell = Cell(row["env"], row["method"], int(row["seed"]), row.get("layouts"))
                rows[cell.key] = row
    return rows


def _write_results(out: Path, rows: dict[str, dict[str, Any]]) -> None:
    write_atomic(out / RESULTS_FILE, "".join(json.dumps(r) + "\n" for r in rows.values()))


def _stale(config: dict[str, Any]) -> list[str]:
    """Settings in which a finished cell's ``config.json`` differs from the requested config."""
    return config_differences(config["run_dir"], asdict(resolve_config(RunConfig(**config))))


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
        overrides: Trainer settings for every cell (``RunConfig`` fields).
        method_options: ``RunConfig.method_options`` of every cell.
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
    from tqdm.auto import tqdm

    if backend not in backends.BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; expected one of {backends.BACKENDS}")
    load_plugins(plugins)
    unknown = sorted({c.method for c in cells} - set(available()))
    if unknown:
        raise ConfigError(f"unknown method(s) {', '.join(unknown)}; registered: "
                         f"{', '.join(available())} (a plugin may register more)")  # fmt: skip
    cores = backends.available_cores()
    local_jobs = max(1, jobs or cores)
    threads = int(threads or max(1, cores // local_jobs))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    configs = [cell_config(c, out, overrides, threads, method_options) for c in cells]
    for cfg in configs:  # every setting checked before any cell starts
        resolve_config(RunConfig(**cfg))
    finished = [(Path(cfg["run_dir"]) / FINAL).exists() for cfg in configs]
    stale = [f"{c.key} ({', '.join(diff)})" for c, cfg, f in zip(cells, configs, finished)
             if f and (diff := _stale(cfg))]  # fmt: skip
    if stale:
        raise ConfigError(f"finished cells of another config under {out}: {'; '.join(stale)};"
                         " use another --out or delete them")  # fmt: skip

    rows = read_results(out)
    for cell, cfg, done in zip(cells, configs, finished):
        if done and rows.get(cell.key, {}).get("status") != "done":  # finished outside bench
            final = read_json(Path(cfg["run_dir"]) / FINAL)
            rows[cell.key] = result_row(cfg, final, None, cached_only=True)
    todo = [i for i, done in enumerate(finished) if not done]
    tasks = [configs[i] for i in todo]
    _write_results(out, rows)

    t0 = time.perf_counter()
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    failed: list[str] = []
    ran = 0
    # This session's line in bench_log.jsonl is written now and rewritten after every cell,
    # so a session killed mid-grid still leaves its time up to its last finished cell.
    log_line = len(_read_lines(out / BENCH_LOG))

    def log(finished: bool) -> dict[str, Any]:
        summary = {
            "started": started, "wall_s": time.perf_counter() - t0, "backend": backend,
            "jobs": jobs or local_jobs, "threads": threads, "cells": len(cells), "ran": ran,
            "skipped": len(cells) - len(todo), "failed": failed, "finished": finished,
            "argv": sys.argv[1:], "results": str(out / RESULTS_FILE),
        }  # fmt: skip
        _write_log_line(out / BENCH_LOG, log_line, summary)
        return summary

    log(False)
    bar = tqdm(total=len(cells), initial=len(cells) - len(todo), desc="abco bench", unit="cell",
               disable=quiet)  # fmt: skip
    runner = (
        backends.run_local(run_cell, tasks, plugins, min(local_jobs, max(len(tasks), 1)))
        if backend == "local" else backends.run_ray(run_cell, tasks, plugins, jobs, address)
    )  # fmt: skip
    if tasks:
        for i, outcome in runner:
            if isinstance(outcome, BaseException):  # the worker died (e.g. out of memory)
                row = result_row(tasks[i], None, None,
                                 error=f"{type(outcome).__name__}: {outcome}")  # fmt: skip
            else:
                row = outcome
            cell = cells[todo[i]]
            row["backend"] = backend
            rows[cell.key] = row
            _write_results(out, rows)
            bar.update(1)
            ran += int(row["status"] == "done")
            if row["status"] != "done":
                failed.append(cell.key)
                why = row.get("error") or (row.get("final") or {}).get("message")
                bar.write(f"{cell.key}: FAILED, {row['status']} ({why})")
            elif not quiet:
                score = headline(row["final"])
                bar.write(f"{cell.key}: P={score['performance']:.3f} AER={score['aer']:.3f}"
                          f" in {row['wall_s']:.1f}s")  # fmt: skip
            log(False)
    bar.close()
    summary = log(True)
    wall = summary["wall_s"]
    if not quiet:
        cell_s = sum(rows[cells[todo[i]].key].get("wall_s") or 0.0 for i in range(len(todo)))
        print(f"{summary['ran']} cells run, {summary['skipped']} skipped, {len(failed)} failed;"
              f" wall {wall:.1f}s (cells {cell_s:.1f}s); results: {summary['results']}")
    return summary


def _read_lines(path: Path) -> list[str]:
    return [x for x in path.read_text().splitlines() if x.strip()] if path.exists() else []


def _write_log_line(path: Path, index: int, summary: dict[str, Any]) -> None:
    """Put ``summary`` at line ``index`` of the bench log (appended if the log is shorter),
    atomically, so the log is never half-written."""
    lines = _read_lines(path)
    lines[index:index + 1] = [json.dumps(summary)]
    write_atomic(path, "\n".join(lines) + "\n")


def headline(final: dict[str, Any]) -> dict[str, float]:
    """The final evaluation of the table: mazes, train split, paper protocol; else episodes."""
    for key in ("train/paper", "episodes"):
        if key in final:
            return final[key]
    return next(v for v in final.values() if isinstance(v, dict) and "performance" in v)
