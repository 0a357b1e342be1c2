"""The one read handle of a :class:`~abco_data.dataset.Dataset` or a torch view.

:class:`LazyH5File` is opened on first use in the process that reads (h5py handles must not
cross a fork), and pinned to one file (:class:`FileIdentity`): a ``DataLoader`` worker that
opens the path again after the file was replaced on disk gets a
:class:`~abco_data.errors.DatasetChangedError`, never rows of another file.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, NamedTuple

import h5py

from abco_data.errors import DatasetChangedError
from abco_data.format.reader import ObservationReader, hdf5_errors, open_h5_file

__all__ = ["FileIdentity", "LazyH5File"]


class FileIdentity(NamedTuple):
    """Which file an open handle reads: device, inode, size and modification time.

    Every writer of abco replaces a file by renaming a new one onto its name, which gives the
    name another inode; a file changed in place changes its size or modification time.
    """

    device: int
    inode: int
    size: int
    mtime_ns: int

    @classmethod
    def of(cls, f: h5py.File) -> FileIdentity:
        """The identity of the file an open h5py handle reads (the handle's own descriptor,
        not its path: the name may already point elsewhere)."""
        return cls.of_descriptor(f.id.get_vfd_handle())

    @classmethod
    def of_descriptor(cls, fd: int) -> FileIdentity:
        """The identity of the file open as descriptor ``fd``."""
        st = os.fstat(fd)
        return cls(st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


class LazyH5File:
    """A read-only h5py handle on ``path``, opened on first use by the process that uses it.

    After a fork (a ``DataLoader`` worker) the child opens its own handle instead of using
    the parent's; pickling drops the handle. :meth:`close` closes it; the next use reopens.
    Every handle is pinned to one file: the first one opened (or ``identity``, the file a
    reader opened before), and a later open that finds another file under ``path`` (the
    dataset was replaced on disk), or an open handle whose file was rewritten in place since,
    raises :class:`~abco_data.errors.DatasetChangedError` instead of mixing rows of two files
    (one ``fstat`` per use: a microsecond).

    Args:
        path: The dataset file.
        identity: The file to pin to; default the first one opened.

    Example:
        >>> import tempfile, os, h5py, numpy as np
        >>> path = os.path.join(tempfile.mkdtemp(), "x.h5")
        >>> with h5py.File(path, "w") as f:
        ...     f["observations"] = np.arange(3)
        >>> handle = LazyH5File(path)
        >>> handle.is_open, int(handle.file()["observations"][2]), handle.is_open
        (False, 2, True)
        >>> handle.observations().read().tolist()
        [0, 1, 2]
        >>> handle.close(); handle.is_open
        False
    """

    def __init__(self, path: str | os.PathLike[str], identity: FileIdentity | None = None
                 ) -> None:
        self.path = Path(path)
        self.identity = identity
        self._file: h5py.File | None = None
        self._reader: ObservationReader | None = None
        self._pid = -1
        self._fd = -1

    @property
    def is_open(self) -> bool:
        """Whether this process holds an open handle."""
        return self._file is not None and self._pid == os.getpid()

    def file(self) -> h5py.File:
        """The handle of this process, opened now if needed.

        Raises:
            DatasetChangedError: Another file than the pinned one is at ``path`` now, or the
                open file changed since.
        """
        f = self._file if self.is_open else None
        if f is None:
            # A handle inherited over a fork belongs to the parent: forget it, never close it.
            self._file, self._reader = None, None
            f = open_h5_file(self.path)
            fd = f.id.get_vfd_handle()
            found = FileIdentity.of_descriptor(fd)
            if self.identity is None:
                self.identity = found
            if found != self.identity:
                f.close()
                raise self._changed()
            self._file, self._pid, self._fd = f, os.getpid(), fd
        elif FileIdentity.of_descriptor(self._fd) != self.identity:  # rewritten in place
            self.close()
            raise self._changed()
        return f

    def _changed(self) -> DatasetChangedError:
        return DatasetChangedError(
            f"{self.path} changed on disk after it was opened (another file, or new bytes, now"
            " has its name); its rows would not match the index read from the first one: open"
            " the dataset again")

    def observations(self) -> ObservationReader:
        """The observations column of this process's handle (a palette decoded on read)."""
        f = self.file()
        if self._reader is None:
            with hdf5_errors(self.path, "observations"):
                self._reader = ObservationReader(f)
        return self._reader

    def close(self) -> None:
        """Close this process's handle, if open."""
        f, self._file, self._reader = self._file if self.is_open else None, None, None
        if f is not None:
            f.close()

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "identity": self.identity, "_file": None, "_reader": None,
                "_pid": -1, "_fd": -1}
