"""One fetch of a dataset at a time: the lock two processes take before filling the cache.

Without it, two processes that fetch the same dataset into an empty cache (two cells of an
``abco bench`` grid) both generate it, and the second one's atomic rename replaces the file the
first one already has open. With it, the second waits, then finds the first one's verified
copy. The lock files live in the temporary folder (one folder per user, each file named by a
digest of the target's path), so the cache holds datasets only; the operating system releases
a lock when its process ends, however it ends.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from filelock import FileLock, Timeout

from abco_data.errors import DatasetNotAvailableError

__all__ = ["acquire_fetch_lock", "FETCH_LOCK_TIMEOUT"]

#: Seconds a fetch waits for another process fetching the same dataset (a download or a
#: generation of the largest dataset takes minutes).
FETCH_LOCK_TIMEOUT = 3600.0


@contextlib.contextmanager
def acquire_fetch_lock(target: Path, dataset_id: str,
                       cache_error: Callable[[OSError, Path], OSError]) -> Iterator[None]:
    """Hold the fetch lock of the cache file ``target`` for the ``with`` block.

    Raises:
        DatasetNotAvailableError: Another process has held it for :data:`FETCH_LOCK_TIMEOUT`.
        OSError: ``cache_error(err, target)`` where the lock's folder or the cache's folder
            cannot be made.
    """
    user = getattr(os, "getuid", lambda: "user")()
    folder = Path(tempfile.gettempdir()) / f"abco-fetch-locks-{user}"
    name = hashlib.sha256(str(target.resolve()).encode()).hexdigest()[:24]
    lock = FileLock(str(folder / f"{name}.lock"), timeout=FETCH_LOCK_TIMEOUT)
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        target.parent.mkdir(parents=True, exist_ok=True)
        lock.acquire()
    except Timeout:
        raise DatasetNotAvailableError(
            f"another process has been fetching {dataset_id} into {target} for "
            f"{FETCH_LOCK_TIMEOUT:.0f} s; try again when it is done") from None
    except OSError as err:
        raise cache_error(err, target) from err
    try:
        yield
    finally:
        lock.release()
