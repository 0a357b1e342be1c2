"""The two files of an ``abco bench`` grid's folder: ``results.jsonl`` and ``bench_log.jsonl``.

* ``results.jsonl``: one JSON line per cell (:func:`result_row`: the cell, its status, its
  final evaluation, the datasets' reference returns, its wall time), rewritten atomically
  after every cell; the latest row of a cell wins (:func:`read_results`).
* ``bench_log.jsonl``: one JSON line per ``abco bench`` invocation (when it started, its wall
  time, backend, jobs, threads, cells run, skipped and failed), each rewritten in place
  (:func:`write_log_line`) so that a killed session still leaves its time up to its last
  finished cell; ``abco report`` sums them (:func:`read_log`).

Both are read by ``abco report`` (:mod:`abco_train.report`); the grid runner
(:mod:`abco_train.bench.grid`) writes them.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from abco_train.bench.cells import Cell
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
    """The final evaluation of the table: mazes, train split, paper protocol; else episodes."""
    for key in ("train/paper", "episodes"):
        if key in final:
            return final[key]
    return next(v for v in final.values() if isinstance(v, dict) and "performance" in v)


def read_results(out: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """The rows of ``out/results.jsonl`` by cell key (the latest row of a cell wins)."""
    rows: dict[str, dict[str, Any]] = {}
    for line in _lines(Path(out) / RESULTS_FILE):
        row = json.loads(line)
        cell = Cell(row["env"], row["method"], int(row["seed"]), row.get("layouts"))
        rows[cell.key] = row
    return rows


def write_results(out: str | os.PathLike[str], rows: dict[str, dict[str, Any]]) -> None:
    """Write ``out/results.jsonl`` (atomically): one line per row, in ``rows``' order."""
    write_atomic(Path(out) / RESULTS_FILE, "".join(json.dumps(r) + "\n" for r in rows.values()))


def read_log(out: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The sessions of ``out/bench_log.jsonl``, oldest first (none without the file)."""
    return [json.loads(x) for x in _lines(Path(out) / BENCH_LOG)]


def log_size(out: str | os.PathLike[str]) -> int:
    """The number of sessions in ``out/bench_log.jsonl``: the line a new session takes."""
    return len(_lines(Path(out) / BENCH_LOG))


def write_log_line(out: str | os.PathLike[str], index: int, summary: dict[str, Any]) -> None:
    """Put ``summary`` at line ``index`` of ``out/bench_log.jsonl`` (appended if the log is
    shorter), atomically, so the log is never half-written."""
    path = Path(out) / BENCH_LOG
    lines = _lines(path)
    lines[index:index + 1] = [json.dumps(summary)]
    write_atomic(path, "\n".join(lines) + "\n")


def _lines(path: Path) -> list[str]:
    """The non-blank lines of ``path`` (none when it does not exist)."""
    return [x for x in path.read_text().splitlines() if x.strip()] if path.exists() else []
