"""One writer per grid: the lock an ``abco bench`` session holds on its ``--out`` folder.

:func:`grid_lock` takes an operating-system lock (``filelock``, ``flock`` on Unix) on
``OUT/bench.lock`` for the whole session and writes who holds it (process id, host, since
when, the command) into ``OUT/bench.lock.holder``. A second session on the same folder is
refused at once with one line naming the holder, never kept waiting. The operating system
drops the lock when its process ends, however it ends, so a killed session never blocks the
next one; the holder file it leaves behind is rewritten by the next holder. The cells' own
run folders are locked by the trainer, each by its own process.

Example:
    >>> import tempfile
    >>> out = Path(tempfile.mkdtemp())
    >>> with grid_lock(out):
    ...     with grid_lock(out):  # doctest: +ELLIPSIS
    ...         pass
    Traceback (most recent call last):
    ...
    abco_train.bench.lock.GridInUseError: ... is in use by pid ...
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from abco_train.harness.run_lock import RunFolderInUseError, folder_lock
from abco_train.harness.run_lock import holder_text as folder_holder_text

__all__ = ["LOCK_FILE", "HOLDER_FILE", "GridInUseError", "grid_lock", "holder_text"]

LOCK_FILE = "bench.lock"
HOLDER_FILE = "bench.lock.holder"


class GridInUseError(RunFolderInUseError):
    """Another ``abco bench`` session holds the grid's folder; the message names it."""


def grid_lock(out: str | os.PathLike[str]) -> Any:
    """Hold the lock of the grid folder ``out`` for a ``with`` block
    (:func:`abco_train.harness.run_lock.folder_lock`).

    Raises:
        GridInUseError: Another process holds it (refused at once; the message names it).
        RunFolderError: Its lock file is a link, a folder or a device (left as it is).
        OSError: The lock cannot be taken (a read-only folder, a full disk).
    """
    command = " ".join(["abco", *sys.argv[1:]])[:500]
    return folder_lock(out, command, lock_file=LOCK_FILE, error=GridInUseError,
                       advice="wait for it to finish or use another --out")  # fmt: skip


def holder_text(out: str | os.PathLike[str]) -> str:
    """Who holds the grid ``out``: ``pid 1234 on host (abco bench ..., since ...)``."""
    return folder_holder_text(Path(out), LOCK_FILE)
