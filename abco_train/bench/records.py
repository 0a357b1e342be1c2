"""The records of a grid, read defensively: size-capped JSON, each record checked against its
schema, and text from records escaped before it is printed.

A grid's folder is shared and copied around, so everything in it is untrusted input:
``results.jsonl`` rows, ``bench_log.jsonl`` lines, and each cell's ``final.json``,
``config.json`` and ``metrics.jsonl``. :func:`read_json` and :func:`read_json_lines` read only
regular files of bounded size (a ``final.json`` linked to ``/dev/zero`` is refused at once,
never read); the ``check_*`` functions raise :class:`RecordError` naming what is wrong (a
missing key, a wrong type, a number that is not finite, a seed out of range). ``abco report``
skips a bad record and counts it (:class:`Skipped`); ``abco bench`` refuses to reuse one.
:func:`escape` writes control characters as escapes, so a record cannot forge an output line.

Example:
    >>> seed_of("seed3"), seed_of("seed٣"), seed_of("seed²"), seed_of("seed03")
    (3, None, None, None)
    >>> escape("ok\\nerror: forged")
    'ok\\\\nerror: forged'
    >>> check_log_line({"wall_s": float("nan")})
    Traceback (most recent call last):
    ...
    abco_train.bench.records.RecordError: wall_s is not a finite number
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from abco_train.config.limits import MAX_BUDGET, MAX_ITERATIONS, MAX_SEED
from abco_train.config.run import MAX_LAYOUTS
from abco_train.harness.run_folder import RunFolderError, open_regular

__all__ = [
    "MAX_RECORD_BYTES", "MAX_LOG_BYTES", "RecordError", "Skipped", "escape", "seed_of",
    "layouts_of", "check_name", "read_bytes", "read_json", "read_json_lines", "check_cell_row",
    "check_row", "check_final", "check_log_line", "check_config", "check_metrics_line",
]  # fmt: skip

#: Largest ``final.json`` / ``config.json``, and largest line of a ``.jsonl`` file (a maze
#: cell's ``final.json`` is about 20 KB; 10,000 evaluation episodes make it about 2 MB).
MAX_RECORD_BYTES = 16 * 2**20
#: Largest ``results.jsonl``, ``bench_log.jsonl`` or ``metrics.jsonl`` (a 235-cell grid's
#: ``results.jsonl`` is 1.7 MB).
MAX_LOG_BYTES = 2**30
#: Most actions of a label distribution (abco's envs have 2 to 5; each is a line of a plot).
MAX_ACTIONS = 64
#: Most episodes of one evaluation's per-episode lists (ten times the most evaluation
#: episodes a run may ask for).
MAX_EPISODE_VALUES = 100_000
#: Largest integer in a record (interaction counts, seeds): exact as a float.
MAX_INT = 2**53
_STATUS = re.compile(r"[A-Za-z0-9_.-]{1,64}")
_SEED = re.compile(r"seed(0|[1-9][0-9]{0,9})", re.ASCII)
_LAYOUTS = re.compile(r"layouts([1-9][0-9]{0,9})", re.ASCII)


class RecordError(RunFolderError):
    """A record of a grid that is not what abco writes; the message says what is wrong."""


@dataclass(frozen=True)
class Skipped:
    """A record ``abco report`` skipped: where (relative to the grid's folder) and why."""

    where: str
    reason: str

    def __str__(self) -> str:
        return f"{escape(self.where)}: {escape(self.reason)}"


def escape(text: object, limit: int = 300) -> str:
    """``text`` on one line: control and other non-printable characters as escapes (``\\n``,
    ``\\x1b``, ``\\u2028``), cut to ``limit`` characters (``...`` marks the cut)."""
    out = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii")
                  for c in str(text))  # fmt: skip
    return out if len(out) <= limit else out[: limit - 3] + "..."


def seed_of(name: str) -> int | None:
    """The seed of a ``seed{n}`` folder name (ASCII digits, no leading zero, at most
    :data:`~abco_train.config.run.MAX_SEED`), else ``None``."""
    m = _SEED.fullmatch(name)
    return int(m.group(1)) if m and int(m.group(1)) <= MAX_SEED else None


def layouts_of(name: str) -> int | None:
    """K of a ``layouts{K}`` folder name (ASCII digits, 1 to ``MAX_LAYOUTS``), else ``None``."""
    m = _LAYOUTS.fullmatch(name)
    return int(m.group(1)) if m and int(m.group(1)) <= MAX_LAYOUTS else None


def check_name(value: Any, what: str) -> str:
    """An env or method name: printable text, no path separator, 1-200 characters."""
    if value is None:
        raise RecordError(f"no {what}")
    if not isinstance(value, str) or not 0 < len(value) <= 200:
        raise RecordError(f"{what} is not a name")
    if not value.isprintable() or "/" in value or "\\" in value or value in (".", ".."):
        raise RecordError(f"{what} {escape(value, 60)!r} is not a valid name")
    return value


# -- reading ----------------------------------------------------------------------------------


def read_bytes(path: Path, cap: int) -> bytes:
    """The bytes of a regular file of at most ``cap`` bytes (``FileNotFoundError`` if absent),
    opened as the run folder opens its files (:func:`abco_train.harness.run_folder.open_regular`).

    Raises:
        RecordError: Not a regular file, too large, or unreadable.
    """
    try:
        handle = open_regular(path)
    except FileNotFoundError:
        raise
    except RunFolderError:  # a device, FIFO or folder: never read
        raise RecordError("not a regular file") from None
    except OSError as exc:
        raise RecordError(f"cannot be read ({exc.strerror or exc})") from None
    with handle:
        size = os.fstat(handle.fileno()).st_size
        if size > cap:
            raise RecordError(f"{size:,} bytes, over the limit of {cap:,}")
        try:
            data = handle.read(cap + 1)
        except OSError as exc:
            raise RecordError(f"cannot be read ({exc.strerror or exc})") from None
    if len(data) > cap:
        raise RecordError(f"over the limit of {cap:,} bytes")
    return data


def _parse(data: bytes | str) -> Any:
    try:
        return json.loads(data.decode("utf-8") if isinstance(data, bytes) else data)
    except UnicodeDecodeError:
        raise RecordError("not UTF-8 text") from None
    except RecursionError:
        raise RecordError("nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, or an integer of too many digits
        raise RecordError(f"not JSON ({escape(exc, 80)})") from None


def read_json(path: str | os.PathLike[str], cap: int = MAX_RECORD_BYTES) -> Any:
    """A JSON file of at most ``cap`` bytes (``FileNotFoundError`` when absent).

    Raises:
        RecordError: Not a regular file, too large, not UTF-8, or not JSON.
    """
    return _parse(read_bytes(Path(path), cap))


def read_json_lines(path: str | os.PathLike[str], cap: int = MAX_LOG_BYTES
                    ) -> list[tuple[int, Any]]:  # fmt: skip
    """``(line number, value or RecordError)`` for each non-blank line of a JSON-lines file
    of at most ``cap`` bytes (none when it does not exist).

    Raises:
        RecordError: The file as a whole: not a regular file, too large, or not UTF-8.
    """
    try:
        data = read_bytes(Path(path), cap)
    except FileNotFoundError:
        return []
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise RecordError("not UTF-8 text") from None
    out: list[tuple[int, Any]] = []
    for number, line in enumerate(text.split("\n"), 1):
        if not line.strip():
            continue
        try:
            if len(line) > MAX_RECORD_BYTES:
                raise RecordError(f"a line over {MAX_RECORD_BYTES:,} characters")
            out.append((number, _parse(line)))
        except RecordError as exc:
            out.append((number, exc))
    return out


# -- the schemas ------------------------------------------------------------------------------


def _finite(value: Any, what: str, low: float = -math.inf) -> float:
    if value is None:
        raise RecordError(f"no {what}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RecordError(f"{what} is not a number")
    if isinstance(value, int) and abs(value) > MAX_INT:
        raise RecordError(f"{what} is too large")
    if not math.isfinite(value):
        raise RecordError(f"{what} is not a finite number")
    if value < low:
        raise RecordError(f"{what} is below {low}")
    return float(value)


def _int(value: Any, what: str, low: int = 0, high: int = MAX_INT) -> int:
    if value is None:
        raise RecordError(f"no {what}")
    if isinstance(value, bool) or not isinstance(value, int):
        raise RecordError(f"{what} is not an integer")
    if not low <= value <= high:
        raise RecordError(f"{what} is out of range ({low} to {high:,})")
    return value


def _text(record: dict[str, Any], key: str) -> None:
    if record.get(key) is not None and not isinstance(record[key], str):
        raise RecordError(f"{key} is not text")


def _numbers(value: Any, what: str) -> None:
    if not isinstance(value, list):
        raise RecordError(f"{what} is not a list")
    for i, x in enumerate(value):
        _finite(x, f"{what}[{i}]")


def _object(record: Any) -> dict[str, Any]:
    if not isinstance(record, dict):
        raise RecordError("not a JSON object")
    return record


def _all_finite(record: Any, what: str) -> None:
    """Every number in ``record`` finite and every integer within :data:`MAX_INT`."""
    stack = [(record, what)]
    while stack:
        value, where = stack.pop()
        if isinstance(value, dict):
            stack += [(v, f"{where}.{escape(k, 40)}") for k, v in value.items()]
        elif isinstance(value, list):
            stack += [(v, f"{where}[{i}]") for i, v in enumerate(value)]
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            _finite(value, where)


def _cell_fields(record: dict[str, Any]) -> tuple[str, str, int, int | None]:
    env = check_name(record.get("env"), "env")
    method = check_name(record.get("method"), "method")
    seed = _int(record.get("seed"), "seed", 0, MAX_SEED)
    layouts = record.get("layouts")
    if layouts is not None:
        layouts = _int(layouts, "layouts", 1, MAX_LAYOUTS)
    return env, method, seed, layouts


def _status(record: dict[str, Any], default: str | None = None) -> str:
    status = record.get("status", default)
    if status is None:
        raise RecordError("no status")
    if not isinstance(status, str) or not _STATUS.fullmatch(status):
        raise RecordError("status is not a status name")
    return status


def check_cell_row(row: Any) -> tuple[str, str, int, int | None]:
    """The cell ``(env, method, seed, layouts)`` of a ``results.jsonl`` row (what ``abco
    bench`` needs of a row; the rest is kept as it is)."""
    row = _object(row)
    cell = _cell_fields(row)
    _status(row)
    return cell


def check_row(row: Any) -> dict[str, Any]:
    """A ``results.jsonl`` row as ``abco report`` reads it: its cell, its final evaluation
    (:func:`check_final`), wall time, reference returns, error text."""
    row = _object(row)
    env, method, seed, layouts = check_cell_row(row)
    if row.get("final") is not None:
        check_final(row["final"], (env, method, seed, layouts))
    if row.get("wall_s") is not None:
        _finite(row["wall_s"], "wall_s", 0.0)
    for key in ("error", "traceback", "host", "backend", "reused_from", "run_dir"):
        _text(row, key)
    for key in ("threads", "pid"):
        if row.get(key) is not None:
            _int(row[key], key)
    if row.get("reference") is not None:
        _reference(_object(row["reference"]))
    return row


def _reference(ref: dict[str, Any]) -> None:
    _all_finite(ref, "reference")
    if "expert" in ref or "random" in ref:
        _finite(ref.get("expert"), "reference.expert")
        _finite(ref.get("random"), "reference.random")
    for split in ("train", "test"):
        if split in ref:
            part = _object(ref[split])
            _finite(part.get("expert"), f"reference.{split}.expert")
            _finite(part.get("random"), f"reference.{split}.random")
            _int(part.get("layouts"), f"reference.{split}.layouts")
    if ref.get("expert_actions") is not None:
        _numbers(ref["expert_actions"], "reference.expert_actions")
        if len(ref["expert_actions"]) > MAX_ACTIONS:
            raise RecordError(f"reference.expert_actions has more than {MAX_ACTIONS} actions")


def check_final(final: Any, cell: tuple[str, str, int, int | None] | None = None
                ) -> dict[str, Any]:  # fmt: skip
    """A ``final.json``: its cell (``cell`` must be it: first the record's env or task), its
    status, every number finite, a finished run (``ok``) with an evaluation holding
    ``performance`` and ``aer``; the benchmark's keys (:func:`_check_benchmark_keys`)."""
    final = _object(final)
    found = _cell_fields(final)
    task = None if final.get("task") is None else check_name(final["task"], "task")
    if cell is not None and tuple(cell) not in (found, (task, *found[1:]),
                                                (task, *found[1:3], None)):  # task's K: no folder
        raise RecordError(f"the record of {_cell_text(found)}, not of {_cell_text(cell)}")
    status = _status(final, "ok")  # records older than the status key: finished
    _all_finite(final, "final")
    _text(final, "message")
    evaluations = {k: v for k, v in final.items() if isinstance(v, dict) and "performance" in v}
    for key, score in evaluations.items():
        _finite(score.get("performance"), f"{escape(key, 40)}.performance")
        _finite(score.get("aer"), f"{escape(key, 40)}.aer")
        if score.get("success_rate") is not None:
            _finite(score["success_rate"], f"{escape(key, 40)}.success_rate")
        if score.get("score") is not None:
            _finite(score["score"], f"{escape(key, 40)}.score")
        for name in ("episode_returns", "episode_performance", "episode_scores"):
            if score.get(name) is not None:
                _numbers(score[name], f"{escape(key, 40)}.{name}")
                if len(score[name]) != score.get("episodes", len(score[name])) or not score[name]:
                    raise RecordError(f"{escape(key, 40)}.{name} does not hold its"
                                      f" {score.get('episodes')} episodes")  # fmt: skip
                if len(score[name]) > MAX_EPISODE_VALUES:
                    raise RecordError(f"{escape(key, 40)}.{name} holds more than"
                                      f" {MAX_EPISODE_VALUES:,} episodes")  # fmt: skip
    if status == "ok" and not evaluations:
        raise RecordError("a finished run's record without any evaluation")
    _check_benchmark_keys(final, evaluations, status)
    counts = final.get("interactions")
    if counts is not None:
        for kind, n in _object(counts).items():
            _int(n, f"interactions.{escape(kind, 40)}")
    return final


def _check_benchmark_keys(final: dict[str, Any], evaluations: dict[str, Any],
                          status: str) -> None:  # fmt: skip
    """``budget`` a positive integer, ``seconds`` at least 0, ``headline`` the key of one of
    the record's evaluations (a finished run's), ``code_version`` two short names."""
    if final.get("budget") is not None:
        _int(final["budget"], "budget", 1, MAX_BUDGET)
    if final.get("seconds") is not None:
        _finite(final["seconds"], "seconds", 0.0)
    headline = final.get("headline")
    if headline is not None and not isinstance(headline, str):
        raise RecordError("headline is not text")
    if headline is not None and status == "ok" and headline not in evaluations:
        raise RecordError(f"headline {escape(headline, 40)!r} is not an evaluation of the record")
    version = final.get("code_version")
    good = isinstance(version, dict) and sorted(version) == ["source", "version"] and all(
        isinstance(v, str) and 0 < len(v) <= 64 and v.isprintable() for v in version.values())
    if version is not None and not good:
        raise RecordError("code_version is not {version, source}, each short printable text")


def _cell_text(cell: tuple[str, str, int, int | None]) -> str:
    env, method, seed, layouts = cell
    where = f"{escape(env, 60)}/{escape(method, 60)}"
    return where + (f"/layouts{layouts}" if layouts is not None else "") + f"/seed{seed}"


def check_log_line(line: Any) -> dict[str, Any]:
    """A ``bench_log.jsonl`` line: its wall time (a finite number of seconds) and the counts."""
    line = _object(line)
    _finite(line.get("wall_s"), "wall_s", 0.0)
    for key in ("started", "backend", "results"):
        _text(line, key)
    for key in ("ran", "skipped", "cells", "jobs", "threads"):
        if line.get(key) is not None:
            _int(line[key], key)
    if line.get("finished") is not None and not isinstance(line["finished"], bool):
        raise RecordError("finished is not true or false")
    for key in ("failed", "argv"):
        value = line.get(key)
        if value is not None and not (isinstance(value, list)
                                      and all(isinstance(x, str) for x in value)):
            raise RecordError(f"{key} is not a list of text")
    return line


def check_config(config: Any) -> dict[str, Any]:
    """A ``config.json`` as the report reads it: an object whose ``regime`` and ``preset``,
    where present, are names."""
    config = _object(config)
    for key in ("regime", "preset"):
        if key in config and not (isinstance(config[key], str) and _STATUS.fullmatch(config[key])):
            raise RecordError(f"{key} is not a name")
    return config


def check_metrics_line(record: Any) -> dict[str, Any]:
    """A ``metrics.jsonl`` line as the report plots it: its iteration, the evaluation's P and
    the IDM's label distribution (training statistics may be NaN: not checked)."""
    record = _object(record)
    _int(record.get("iteration"), "iteration", 0, MAX_ITERATIONS)
    evaluation = record.get("eval")
    if evaluation is not None and _object(evaluation).get("performance") is not None:
        _finite(evaluation["performance"], "eval.performance")
    shares = record.get("label_distribution")
    if shares is not None:
        _numbers(shares, "label_distribution")
        if len(shares) > MAX_ACTIONS:
            raise RecordError(f"label_distribution has more than {MAX_ACTIONS} actions")
    return record
