"""The two files of an ``abco bench`` grid's folder: ``results.jsonl`` and ``bench_log.jsonl``.

* ``results.jsonl``: one JSON line per cell (:func:`result_row`: the cell, its status, its
  final evaluation, the datasets' reference returns, its wall time), rewritten atomically
  after every cell; the latest row of a cell wins (:func:`read_results`).
* ``bench_log.jsonl``: one JSON line per ``abco bench`` invocation (when it started, its wall
  time, backend, jobs, threads, cells run, skipped and failed), each rewritten in place
  (:func:`write_log_line`) so that a killed session still leaves its time up to its last
  finished cell; ``abco report`` sums them (:func:`read_log`).

Both are read by ``abco report`` (:mod:`abco_train.report`), every line checked
(:mod:`abco_train.bench.records`): the report skips a damaged one and counts it. The grid runner
(:mod:`abco_train.bench.grid`) writes them under the grid's lock; it refuses a damaged row of
``results.jsonl`` (rewriting the file would drop it) and keeps every line of the log as it is.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from abco_train.bench.cells import Cell
from abco_train.bench.records import (
    MAX_LOG_BYTES,
    RecordError,
    Skipped,
    check_cell_row,
    check_log_line,
    check_row,
    escape,
    read_bytes,
    read_json_lines,
)
from abco_train.harness.run_folder import write_atomic
from abco_train.harness.training_data import KINDS, resolve_dataset

__all__ = ["RESULTS_FILE", "BENCH_LOG", "result_row", "headline", "read_results",
           "write_results", "read_log", "log_size", "write_log_line"]  # fmt: skip

RESULTS_FILE = "results.jsonl"
BENCH_LOG = "bench_log.jsonl"


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
        **({"task": config["task"]} if config.get("task") is not None else {}),
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


def headline(final: dict[str, Any]) -> dict[str, float]:
    """The final evaluation of the table: the block the record names as its ``headline``, else
    (older records) mazes' train split under the paper protocol, or ``episodes``."""
    named = final.get("headline")
    if isinstance(named, str) and isinstance(final.get(named), dict):
        return final[named]
    for key in ("train/paper", "episodes"):
        if key in final:
            return final[key]
    return next(v for v in final.values() if isinstance(v, dict) and "performance" in v)


def read_results(out: str | os.PathLike[str], skipped: list[Skipped] | None = None
                 ) -> dict[str, dict[str, Any]]:  # fmt: skip
    """The rows of ``out/results.jsonl`` by cell key (the latest row of a cell wins).

    Args:
        out: The grid's folder.
        skipped: Where a damaged row goes (:class:`~abco_train.bench.records.Skipped`; every
            row checked as the report reads it, :func:`~abco_train.bench.records.check_row`);
            ``None``: a row whose cell cannot be read is an error (``abco bench``, which
            rewrites the file, never drops a row).

    Raises:
        RecordError: ``skipped`` is ``None`` and the file or a row is damaged (the message
            names the line).
    """
    path = Path(out) / RESULTS_FILE
    rows: dict[str, dict[str, Any]] = {}
    for number, row in _records(path, skipped):
        try:
            if isinstance(row, RecordError):
                raise row
            env, method, seed, layouts = check_cell_row(row) if skipped is None else \
                _row_cell(check_row(row))  # fmt: skip
        except RecordError as exc:
            if skipped is None:
                raise RecordError(f"{escape(path)} line {number}: {exc}; repair or remove that"
                                  " line") from None  # fmt: skip
            skipped.append(Skipped(f"{RESULTS_FILE} line {number}", str(exc)))
            continue
        task = row.get("task") if isinstance(row, dict) and isinstance(row.get("task"), str) \
            else None  # fmt: skip
        rows[Cell(env, method, seed, layouts, task).key] = row
    return rows


def _row_cell(row: dict[str, Any]) -> tuple[str, str, int, int | None]:
    return row["env"], row["method"], row["seed"], row.get("layouts")


def _records(path: Path, skipped: list[Skipped] | None) -> list[tuple[int, Any]]:
    """The lines of a JSON-lines file of the grid; a file that cannot be read at all is an
    error (``skipped`` ``None``) or skipped."""
    try:
        return read_json_lines(path)
    except RecordError as exc:
        if skipped is None:
            raise RecordError(f"{escape(path)}: {exc}") from None
        skipped.append(Skipped(path.name, str(exc)))
        return []


def write_results(out: str | os.PathLike[str], rows: dict[str, dict[str, Any]]) -> None:
    """Write ``out/results.jsonl`` (atomically): one line per row, in ``rows``' order."""
    write_atomic(Path(out) / RESULTS_FILE, "".join(json.dumps(r) + "\n" for r in rows.values()))


def read_log(out: str | os.PathLike[str], skipped: list[Skipped] | None = None
             ) -> list[dict[str, Any]]:  # fmt: skip
    """The sessions of ``out/bench_log.jsonl``, oldest first (none without the file), each
    checked (:func:`~abco_train.bench.records.check_log_line`).

    Args:
        out: The grid's folder.
        skipped: Where a damaged line goes; ``None``: a damaged line is an error.

    Raises:
        RecordError: ``skipped`` is ``None`` and the file or a line is damaged.
    """
    path = Path(out) / BENCH_LOG
    sessions = []
    for number, line in _records(path, skipped):
        try:
            if isinstance(line, RecordError):
                raise line
            sessions.append(check_log_line(line))
        except RecordError as exc:
            if skipped is None:
                raise RecordError(f"{escape(path)} line {number}: {exc}") from None
            skipped.append(Skipped(f"{BENCH_LOG} line {number}", str(exc)))
    return sessions


def log_size(out: str | os.PathLike[str]) -> int:
    """The number of sessions in ``out/bench_log.jsonl``: the line a new session takes."""
    return len(_lines(Path(out) / BENCH_LOG))


def write_log_line(out: str | os.PathLike[str], index: int, summary: dict[str, Any]) -> None:
    """Put ``summary`` at line ``index`` of ``out/bench_log.jsonl`` (appended if the log is
    shorter), atomically, so the log is never half-written; every other line is kept as it
    is."""
    path = Path(out) / BENCH_LOG
    lines = _lines(path)
    lines[index:index + 1] = [json.dumps(summary)]
    write_atomic(path, "\n".join(lines) + "\n")


def _lines(path: Path) -> list[str]:
    """The non-blank lines of ``path`` as they are (none when it does not exist).

    Raises:
        RecordError: Not a regular file, over the size limit, or not UTF-8 text.
    """
    try:
        data = read_bytes(path, MAX_LOG_BYTES)
    except FileNotFoundError:
        return []
    except RecordError as exc:
        raise RecordError(f"{escape(path)}: {exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise RecordError(f"{escape(path)}: not UTF-8 text") from None
    return [x for x in text.split("\n") if x.strip()]
