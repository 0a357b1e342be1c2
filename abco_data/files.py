"""File-system helpers every writer of abco_data shares: atomic targets and file digests.

Everything abco_data writes (dataset files, cache copies, Minari exports) is first written
under a hidden temporary name next to its target, then moved onto the target with
:func:`os.replace`, which is atomic on one file system: a reader sees the old file or the new
one, never half of one. Temporary names end in :data:`TEMP_SUFFIX`, so they can be told
apart from anything else in a folder.

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
import os
import shutil
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["TEMP_SUFFIX", "atomic_target", "file_digest", "remove_path", "sha256_of",
           "temporary_name"]

#: The suffix of every temporary name abco_data creates.
TEMP_SUFFIX = ".abco-tmp"
_READ_CHUNK = 1 << 20


def temporary_name(target: str | os.PathLike[str], tag: str = "writing") -> Path:
    """A hidden, unique name in ``target``'s folder (same file system: renames are atomic).

    Example:
        >>> name = temporary_name("/data/x.hdf5", "incoming").name
        >>> name.startswith(".x.hdf5.") and name.endswith(".incoming" + TEMP_SUFFIX)
        True
    """
    target = Path(target)
    return target.with_name(f".{target.name}.{uuid.uuid4().hex[:12]}.{tag}{TEMP_SUFFIX}")


def remove_path(path: Path) -> None:
    """Remove a file, a link or a folder tree at ``path`` if there is one (never following a
    link: a link is removed, not what it points to)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _fsync(path: Path) -> None:
    with open(path, "rb") as handle:
        os.fsync(handle.fileno())


@contextmanager
def atomic_target(target: str | os.PathLike[str], tag: str = "writing") -> Iterator[Path]:
    """Yield a temporary path next to ``target``; move what was written there onto ``target``.

    The block writes a file or a folder at the yielded path. When it exits normally, a file
    is flushed to disk (``fsync``) and moved onto ``target`` with :func:`os.replace`; a folder
    replaces a folder ``target`` (the old one is moved aside first, then removed). When the
    block raises, the temporary is removed and ``target`` is left as it was.

    Args:
        target: The final path; its folder is created if needed.
        tag: A word in the temporary name saying what it is for.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_name(target, tag)
    try:
        yield tmp
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
    """Return ``(size in bytes, hex sha256)`` of a file, read in 1 MiB chunks."""
    digest = hashlib.sha256()
    size = 0
    with open(path, "rb") as handle:
        while chunk := handle.read(_READ_CHUNK):
            digest.update(chunk)
            size += len(chunk)
    return size, digest.hexdigest()


def sha256_of(path: str | os.PathLike[str]) -> str:
    """Hex sha256 of a file: the second half of :func:`file_digest`."""
    return file_digest(path)[1]
