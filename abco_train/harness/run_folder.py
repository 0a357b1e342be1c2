"""The run folder's layout, in one place, and the reads that need no torch.

A run folder holds::

    config.json        the resolved config
    metrics.jsonl      one line per iteration: training stats, evaluation, I_s composition,
                       the IDM's label distribution on the expert data, seconds
    checkpoint.pt      the latest iteration's full state (method, rngs); re-running the same
                       command resumes after it
    final.json         the final evaluation (mazes: train and test splits, both protocols)
    metrics.png, labels.png, paths_{split}.png   the plots
    run.lock, run.lock.holder   the lock of the one process writing it, and who that is
                       (:mod:`abco_train.harness.run_lock`)

Files are written whole or not at all (:func:`write_atomic`, on
:func:`abco_data.format.files.atomic_target`): a killed run, a full disk or a read-only folder never
leaves a half-written ``final.json``, checkpoint or plot, and the temporaries of killed runs are
removed on the next write. Only a regular file (or a new path) is ever replaced: a run folder
that is not a folder, or a device, a FIFO or a link where one of its files goes, is refused
before any work (:func:`check_run_dir`).

A run folder may come from elsewhere, so its files are read defensively: only regular files,
at most :data:`MAX_JSON_BYTES` of JSON (:func:`read_json`), a ``final.json`` counted only when
it is a finished run's record of the very config asked for (:func:`finished_result`).
"""

from __future__ import annotations

import json
import math
import os
import stat
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

from abco_data.errors import InvalidTargetError
from abco_data.format.files import atomic_target, check_target, file_kind
from abco_train.methods.registry import identity

__all__ = ["CONFIG", "METRICS", "CHECKPOINT", "FINAL", "OUTPUTS", "MAX_JSON_BYTES",
           "RunFolderError", "write_atomic", "open_regular", "read_capped", "read_json",
           "check_run_dir", "finished_result", "config_differences"]  # fmt: skip

CONFIG = "config.json"
METRICS = "metrics.jsonl"
CHECKPOINT = "checkpoint.pt"
FINAL = "final.json"
#: Every file a run writes into its folder (plots included).
OUTPUTS = (CONFIG, METRICS, CHECKPOINT, FINAL, "metrics.png", "labels.png", "paths_train.png",
           "paths_test.png", "paths_fresh.png")  # fmt: skip
#: The largest JSON file of a run folder that is read (``config.json``, ``final.json``, ...).
MAX_JSON_BYTES = 64 * 2**20


class RunFolderError(ValueError):
    """The run folder cannot be used as asked (it holds another config, or damaged files)."""


def write_atomic(path: str | os.PathLike[str], write: Callable[[Path], Any] | str) -> Path:
    """Write ``path`` through a temporary file in the same folder, then rename it into place.

    Args:
        path: The destination.
        write: The text to write, or ``write(tmp_path)`` that writes the file itself (e.g.
            ``lambda p: p.write_bytes(data)``).

    Raises:
        RunFolderError: ``path`` is not a new path or a regular file (a device, a FIFO, a
            link, a folder); it is left untouched.
        OSError: The write failed (a full disk, a read-only folder); ``path`` is left as it
            was and no temporary stays behind.
    """
    try:
        with atomic_target(path) as tmp:  # the data layer's one temp-then-rename helper
            if isinstance(write, str):
                tmp.write_text(write)
            else:
                write(tmp)
    except InvalidTargetError as exc:
        raise RunFolderError(str(exc)) from None
    except OSError as exc:  # named by the file it was for, not by its temporary (or nothing)
        if exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror or os.strerror(exc.errno), str(path)) from exc
    return Path(path)


def open_regular(path: str | os.PathLike[str]) -> IO[bytes]:
    """``path`` opened for reading, once it is known to be a regular file (a FIFO is opened
    without waiting for a writer, a device never read).

    Raises:
        RunFolderError: ``path`` is not a regular file (the message says what it is).
        OSError: It cannot be opened (missing, no permission).
    """
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):  # before open(): a folder's descriptor would fail unnamed
        os.close(fd)
        raise RunFolderError(f"{path} is {file_kind(mode)}, not a regular file; abco reads only "
                             "regular files of a run folder")  # fmt: skip
    return open(fd, "rb")  # noqa: SIM115 (handed to the caller, who closes it)


def read_capped(path: str | os.PathLike[str], cap: int) -> bytes:
    """The bytes of the regular file ``path``, refused past ``cap`` bytes before any is read.

    Raises:
        RunFolderError: Not a regular file, or larger than ``cap``.
        OSError: It cannot be read.
    """
    with open_regular(path) as handle:
        size = os.fstat(handle.fileno()).st_size
        data = handle.read(cap + 1) if size <= cap else b""
        if size > cap or len(data) > cap:
            raise RunFolderError(f"{path} holds {max(size, len(data)):,} bytes, more than the "
                                 f"{cap:,} abco reads of it; it is no file abco wrote")  # fmt: skip
    return data


def read_json(path: str | os.PathLike[str], cap: int = MAX_JSON_BYTES) -> Any:
    """A JSON file of a run folder (a regular file of at most ``cap`` bytes).

    Raises:
        RunFolderError: The file is not a regular file, too large, or not valid UTF-8 JSON
            (the message names it).
        OSError: It cannot be read.
    """
    data = read_capped(path, cap)
    try:
        return json.loads(data.decode("utf-8"))
    except RecursionError:
        reason = "nested too deeply"
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError, an over-long integer
        reason = " ".join(str(exc).split())[:200]
    raise RunFolderError(f"{path} is damaged ({reason}); delete it to redo that step")


def check_run_dir(run_dir: str | os.PathLike[str]) -> None:
    """Refuse a run folder that is not a folder (or a new path), and any of its
    :data:`OUTPUTS` that is not a regular file (or absent): nothing is replaced.

    Raises:
        RunFolderError: What is wrong, in one line.
    """
    try:
        mode = os.stat(run_dir).st_mode
    except FileNotFoundError:
        return
    except NotADirectoryError:
        raise RunFolderError(f"run folder {run_dir}: a parent of it is a file") from None
    if not stat.S_ISDIR(mode):
        raise RunFolderError(f"run folder {run_dir} is {file_kind(mode)}, not a folder; use "
                             "another --run-dir")  # fmt: skip
    for name in OUTPUTS:
        check_output(Path(run_dir) / name)


def check_output(path: str | os.PathLike[str]) -> None:
    """Refuse an output path that is not a new path or a regular file (before any work).

    Raises:
        RunFolderError: ``path`` is a device, a FIFO, a socket, a link or a folder.
    """
    try:
        check_target(path)
    except InvalidTargetError as exc:
        raise RunFolderError(str(exc)) from None


def config_differences(run_dir: str | os.PathLike[str], config: dict[str, Any]) -> list[str]:
    """Settings in which the folder's ``config.json`` differs from ``config`` (runtime
    settings aside; both read as :func:`abco_train.methods.registry.identity` reads them, so
    a folder written before a setting moved into the method's options still matches); empty
    when they agree or the folder has no config yet."""
    path = Path(run_dir) / CONFIG
    if not os.path.lexists(path):
        return []
    record = read_json(path)
    if not isinstance(record, dict):
        raise RunFolderError(f"{path} holds no config (a JSON {type(record).__name__}); delete "
                             "it or use another --run-dir")  # fmt: skip
    had, wanted = identity(record), identity(config)
    return sorted(k for k in set(had) | set(wanted) if had.get(k) != wanted.get(k))


def finished_result(run_dir: str | os.PathLike[str], config: dict[str, Any]
                    ) -> dict[str, Any] | None:  # fmt: skip
    """The stored ``final.json`` of a finished run of this very config, else ``None``.

    Raises:
        RunFolderError: ``final.json`` is damaged, or is no finished run's record of this
            config (it is never counted as one, nor replaced).
    """
    final = Path(run_dir) / FINAL
    if not os.path.lexists(final) or config_differences(run_dir, config):
        return None
    record = read_json(final)
    problem = _final_problem(record, config)
    if problem is not None:
        raise RunFolderError(f"{final} is not the record of a finished run of this config "
                             f"({problem}); delete it to redo the final evaluation")  # fmt: skip
    return record


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _final_problem(record: Any, config: Mapping[str, Any]) -> str | None:
    """What keeps ``record`` from being a finished run's ``final.json`` of ``config``: it is
    an object with a status; the env, method and seed it names are the config's; its
    evaluations hold numbers; a failure's message is text."""
    if not isinstance(record, dict):
        return f"a JSON {type(record).__name__}, not an object"
    if not isinstance(record.get("status"), str):
        return "no status"
    for key in ("env", "method", "seed"):
        if key not in record:
            return f"no {key}"
        if record[key] != config.get(key) or isinstance(record[key], bool):
            return f"its {key} is {str(record[key])[:40]!r}, not {config.get(key)!r}"
    if not isinstance(record.get("message", ""), str) or \
            type(record.get("iteration", 0)) is not int:  # fmt: skip
        return "a failure's message or iteration of another type"
    scores = [v for v in record.values() if isinstance(v, dict) and "performance" in v]
    if record["status"] == "ok" and not scores:
        return "a finished run without any evaluation"
    for score in scores:
        if not all(_number(score.get(k)) and math.isfinite(score[k])
                   for k in ("performance", "aer", "success_rate")) \
                or type(score.get("episodes")) is not int:  # fmt: skip
            return "an evaluation without its (finite) numbers"
        if not 0 <= score["success_rate"] <= 1:  # NaN too
            return "an evaluation whose success rate is no share"
    figures, counts = record.get("figures", {}), record.get("interactions", {})
    if not isinstance(figures, dict) or not all(isinstance(v, str) for v in figures.values()):
        return "figures that are not file names"
    if not isinstance(counts, dict) or not all(type(v) is int for v in counts.values()):
        return "interaction counts that are not counts"
    return None
