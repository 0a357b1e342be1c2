"""File-system helpers every writer of abco_data shares: atomic targets and file digests.

Everything abco_data writes (dataset files, cache copies, Minari exports) is first written
under a hidden temporary name next to its target, then moved onto the target with
:func:`os.replace`, which is atomic on one file system: a reader sees the old file or the new
one, never half of one. Only a regular file (or, for a folder, a folder) is ever replaced:
:func:`check_target` refuses a device, a FIFO, a socket or a symbolic link at the target, and
a folder where a file is written, before any work and again just before the rename.
Temporary names end in :data:`TEMP_SUFFIX` and carry the id of the
process writing them, so the ones a killed process left behind can be told apart from
anything else in a folder and removed (:func:`remove_stale_temporaries`, run by
:func:`atomic_target` for its own target and by the cache for its whole folder).

Example:
    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "a.txt"
    >>> with atomic_target(target) as tmp:
    ...     _ = tmp.write_text("hello")
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('hello', ['a.txt'])
    >>> file_digest(target)[0], sha256_of(target)[:12]
    (5, '2cf24dba5fb0')
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import shutil
import stat
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from abco_data.errors import DatasetReadError, InvalidTargetError

__all__ = ["TEMP_SUFFIX", "STALE_AFTER_SECONDS", "atomic_target", "check_target", "file_digest",
           "file_kind", "remove_path", "remove_stale_temporaries", "sha256_of",
           "temporary_name"]

logger = logging.getLogger(__name__)

#: The suffix of every temporary name abco_data creates.
TEMP_SUFFIX = ".abco-tmp"
#: A temporary file this old is stale even if its process id is in use again.
STALE_AFTER_SECONDS = 24 * 3600
_READ_CHUNK = 1 << 20
# ".<target>.<pid>-<hex>.<tag>.abco-tmp"; and the names of abco_data before 0.1.1 (no pid,
# stale after STALE_AFTER_SECONDS): ".<target>.<32 hex>.tmp", ".<stem>.<12 hex>.<tag><suffix>"
_TEMP = re.compile(r"^\.(?P<target>.+)\.(?P<pid>\d+)-[0-9a-f]{8}\.[a-z]+" + re.escape(TEMP_SUFFIX)
                   + "$")
_OLD_TEMP = re.compile(r"^\..+\.([0-9a-f]{32}\.tmp|[0-9a-f]{12}\.(incoming|generating)\..+)$")


def temporary_name(target: str | os.PathLike[str], tag: str = "writing") -> Path:
    """A hidden, unique name in ``target``'s folder (same file system: renames are atomic).

    Example:
        >>> name = temporary_name("/data/x.hdf5", "incoming").name
        >>> name.startswith(f".x.hdf5.{os.getpid()}-") and name.endswith(".incoming.abco-tmp")
        True
    """
    target = Path(target)
    return target.with_name(
        f".{target.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.{tag}{TEMP_SUFFIX}")


def remove_path(path: Path) -> None:
    """Remove a file, a link or a folder tree at ``path`` if there is one, as far as possible.

    Never follows a link (a link is removed, not what it points to) and never raises: it
    cleans up after another error, which must not be masked (a failure is logged).
    """
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    except OSError as err:
        logger.warning("could not remove %s: %s", path, err)


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process (EPERM): alive
        return True
    return True


def remove_stale_temporaries(folder: str | os.PathLike[str], target: str | None = None,
                             *, now: float | None = None) -> list[Path]:
    """Remove the temporaries abco_data left in ``folder`` from processes that died.

    A temporary is stale when the process that made it is gone (same machine), or when it is
    older than :data:`STALE_AFTER_SECONDS`. Nothing else is touched; failures are logged.

    Args:
        folder: The folder to clean.
        target: Only the temporaries of this file name.
        now: The current time (tests).

    Returns:
        The paths removed.
    """
    now = time.time() if now is None else now
    removed = []
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        match = _TEMP.match(name)
        if match is None and _OLD_TEMP.match(name) is None:
            continue
        if target is not None and (match is None or match["target"] != target):
            continue
        path = Path(folder) / name
        try:
            age = now - path.lstat().st_mtime
        except OSError:
            continue
        dead = match is not None and not _process_alive(int(match["pid"]))
        if dead or age > STALE_AFTER_SECONDS:
            remove_path(path)
            removed.append(path)
    if removed:
        logger.info("removed %d stale temporary file(s) from %s", len(removed), folder)
    return removed


def file_kind(mode: int) -> str:
    """What an ``st_mode`` is, in words ("a regular file", "a FIFO (named pipe)", ...)."""
    kinds = ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"),
             (stat.S_ISLNK, "a symbolic link"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
             (stat.S_ISSOCK, "a socket"))
    return next((name for test, name in kinds if test(mode)), "not a regular file")


def check_target(target: str | os.PathLike[str], *, folder: bool = False) -> None:
    """Refuse an output path abco must not replace; a new path or a regular file passes.

    Never follows a symbolic link: a link at ``target`` is refused (replacing it would cut the
    link, and writing through it would change a file elsewhere), as are devices, FIFOs and
    sockets, and a folder unless ``folder`` (the block writes a folder that replaces it).

    Args:
        target: The output path.
        folder: The output is a folder: an existing folder may be replaced, a file may not.

    Raises:
        InvalidTargetError: ``target`` is something else (the message says what).

    Example:
        >>> check_target("/dev/null")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        abco_data.errors.InvalidTargetError: cannot write /dev/null: it is a character device; ...
    """
    try:
        mode = os.lstat(target).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return
    if stat.S_ISDIR(mode) if folder else stat.S_ISREG(mode):
        return
    what = file_kind(mode)
    if stat.S_ISLNK(mode):
        what += f" (to {os.readlink(target)})"
    wanted = "a new path or a folder, which it replaces" if folder else \
        "a new path or a regular file, which it replaces"
    raise InvalidTargetError(f"cannot write {target}: it is {what}; abco writes only to {wanted}")


def _fsync(path: Path) -> None:
    with open(path, "rb") as handle:
        os.fsync(handle.fileno())


@contextmanager
def atomic_target(target: str | os.PathLike[str], tag: str = "writing", *,
                  folder: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``target``; move what was written there onto ``target``.

    The block writes a file or a folder at the yielded path. When it exits normally, a file
    is flushed to disk (``fsync``) and moved onto ``target`` with :func:`os.replace`; a folder
    replaces a folder ``target`` (the old one is moved aside first, then removed). When the
    block raises, the temporary is removed and ``target`` is left as it was. ``target`` is
    checked by :func:`check_target` before the block runs and again before the rename.

    Args:
        target: The final path; its folder is created if needed.
        tag: A word in the temporary name saying what it is for.
        folder: The block writes a folder, which may replace a folder ``target``.

    Raises:
        InvalidTargetError: ``target`` is not a new path or a regular file (a folder, with
            ``folder``); it is left untouched.
    """
    target = Path(target)
    check_target(target, folder=folder)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(target.parent, target.name)
    tmp = temporary_name(target, tag)
    try:
        yield tmp
        if tmp.exists():
            check_target(target, folder=tmp.is_dir())  # nothing else took its place meanwhile
        if tmp.is_dir():
            old = temporary_name(target, "old") if target.exists() else None
            if old is not None:
                os.replace(target, old)
            os.replace(tmp, target)
            if old is not None:
                remove_path(old)
        elif tmp.exists():
            _fsync(tmp)
            os.replace(tmp, target)
    finally:
        remove_path(tmp)


def file_digest(path: str | os.PathLike[str]) -> tuple[int, str]:
    """Return ``(size in bytes, hex sha256)`` of a file, read in 1 MiB chunks.

    Raises:
        DatasetReadError: ``path`` is not a regular file (a FIFO, a device: never read, so
            never waited on).
    """
    digest = hashlib.sha256()
    size = 0
    # Non-blocking open: opening a FIFO for reading would wait for a writer.
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with open(fd, "rb") as handle:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise DatasetReadError(f"{path}: cannot read {file_kind(mode)}: not a regular file")
        while chunk := handle.read(_READ_CHUNK):
            digest.update(chunk)
            size += len(chunk)
    return size, digest.hexdigest()


def sha256_of(path: str | os.PathLike[str]) -> str:
    """Hex sha256 of a file: the second half of :func:`file_digest`."""
    return file_digest(path)[1]
