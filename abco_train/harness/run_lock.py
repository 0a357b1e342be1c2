"""One writer per folder: the lock ``abco train`` (and anything else that writes a run
folder) holds on its run folder, and ``abco bench`` on its grid's folder.

:func:`run_folder_lock` takes an operating-system lock (``filelock``: ``flock`` on Unix) on
``RUN_DIR/run.lock`` for as long as it writes the folder, and writes who holds it (process
id, host, since when, what for) into ``RUN_DIR/run.lock.holder``. A second writer of the same
folder is refused at once with one line naming the holder, never kept waiting. The operating
system drops the lock when its process ends, however it ends, so a killed run never blocks
the next one; the holder file it leaves behind is rewritten by the next holder.

Example:
    >>> import tempfile
    >>> run_dir = Path(tempfile.mkdtemp())
    >>> with run_folder_lock(run_dir, "abco train"):
    ...     with run_folder_lock(run_dir, "abco train"):  # doctest: +ELLIPSIS
    ...         pass
    Traceback (most recent call last):
    ...
    abco_train.harness.run_lock.RunFolderInUseError: ... is in use by pid ... (abco train, since ...
"""

from __future__ import annotations

import json
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from datetime import datetime
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout

from abco_train.harness.run_folder import RunFolderError, check_output, read_json, write_atomic

__all__ = ["LOCK_FILE", "HOLDER_FILE", "RunFolderInUseError", "folder_lock", "run_folder_lock",
           "holder_text"]

LOCK_FILE = "run.lock"
HOLDER_FILE = "run.lock.holder"
#: The most of a holder file that is read (it is a line of JSON).
_HOLDER_CAP = 4096


class RunFolderInUseError(RunFolderError):
    """Another process writes the run folder; the message names it."""


@contextmanager
def folder_lock(folder: str | os.PathLike[str], purpose: str, *, lock_file: str = LOCK_FILE,
                advice: str = "wait for it or use another --run-dir",
                error: type[RunFolderError] = RunFolderInUseError) -> Iterator[None]:  # fmt: skip
    """Hold the lock ``lock_file`` of ``folder`` (created if needed) for the ``with`` block.

    Args:
        folder: The folder one process at a time writes (a run folder, a grid's folder).
        purpose: What the holder does, as the refusal of another writer shows it (e.g.
            ``abco train``).
        lock_file: The lock's file in ``folder``; who holds it is written beside it
            (``{lock_file}.holder``).
        advice: What the refusal tells the second writer to do.
        error: The refusal's class.

    Raises:
        RunFolderInUseError: (or ``error``) Another process, or another block of this one,
            holds it; refused at once, the message names the holder.
        RunFolderError: Its lock file is a link, a FIFO or a device (left as it is).
        OSError: The lock cannot be taken (a read-only folder, a full disk).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    check_output(folder / lock_file)  # a link there would be followed (and emptied)
    lock = FileLock(folder / lock_file)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise error(f"{_clean(folder, 200)} is in use by {holder_text(folder, lock_file)}; "
                    f"{advice}") from None  # fmt: skip
    holder_file, written = folder / f"{lock_file}.holder", False
    try:
        holder = {"pid": os.getpid(), "host": socket.gethostname(), "purpose": purpose,
                  "since": datetime.now().astimezone().isoformat(timespec="seconds")}  # fmt: skip
        write_atomic(holder_file, json.dumps(holder) + "\n")
        written = True
        yield
    finally:
        if written:  # only the file it wrote (a link found there is left as it is)
            with suppress(OSError):
                holder_file.unlink()
        lock.release()


def run_folder_lock(run_dir: str | os.PathLike[str], purpose: str) -> Any:
    """Hold the lock of the run folder ``run_dir`` (:func:`folder_lock`), e.g.
    ``with run_folder_lock(run_dir, "abco train"): ...``."""
    return folder_lock(run_dir, purpose)


def _clean(value: object, limit: int) -> str:
    """``value`` as one short line of printable text (a holder file is read, not trusted)."""
    text = "".join(c if c.isprintable() else "?" for c in str(value))
    return text if len(text) <= limit else text[: limit - 3] + "..."


def holder_text(folder: str | os.PathLike[str], lock_file: str = LOCK_FILE) -> str:
    """Who holds the folder's lock: ``pid 1234 on host (abco train, since ...)``, from its
    holder file (``another process`` when that cannot be read)."""
    try:
        holder = read_json(Path(folder) / f"{lock_file}.holder", cap=_HOLDER_CAP)
    except (OSError, RunFolderError):
        return "another process"
    if not isinstance(holder, dict):
        return "another process"
    pid, host = _clean(holder.get("pid"), 20), _clean(holder.get("host"), 80)
    purpose, since = _clean(holder.get("purpose"), 80), _clean(holder.get("since"), 40)
    return f"pid {pid} on {host} ({purpose}, since {since})"
