"""Checks HDF5 does not make, on the global heaps that hold variable-length strings.

Variable-length strings (every string attribute of an abco file, and the ``reference``
layout ids) live in HDF5 "global heap collections". When HDF5 loads a collection it walks its
objects, each one ``16 + size`` bytes long, and a free-space object (index 0) of size 0 sends
that walk back to where it started: reading any string of the file then never returns (a
single zeroed block is enough). An object size that runs past the collection makes the same
walk read outside it. And a string's stored length (the 4 bytes before its heap id) is what
HDF5 allocates and fills before it compares it with the heap object's: one flipped high byte
costs gigabytes of memory and seconds of time before the error.

:func:`check_global_heaps` walks every collection of a file the way HDF5 does, then finds
every reference to one of their objects (collection address and object index, the way
variable-length data is stored) and checks the length stored with it, and raises
:class:`~abco_data.errors.CorruptDatasetError` where HDF5 would loop, overrun or allocate
more than the object holds, before HDF5 reads anything.

Collections are found by their signature (``GCOL``, version 1), the way HDF5's own recovery
tools find them; the walk follows the layout of the HDF5 file format specification (version
0 and 1 superblocks give the size of lengths at byte 14, versions 2 and 3 at byte 10).

Example:
    >>> import tempfile, os, h5py
    >>> path = os.path.join(tempfile.mkdtemp(), "x.h5")
    >>> with h5py.File(path, "w", libver="earliest") as f:
    ...     f.attrs["name"] = "a string in a global heap"
    >>> check_global_heaps(path)
    >>> data = bytearray(open(path, "rb").read())
    >>> start = data.find(b"GCOL") + 16 + 16 + 32  # past the first object: the free space
    >>> data[start : start + 16] = bytes(16)
    >>> _ = open(path, "wb").write(bytes(data))
    >>> check_global_heaps(path)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    abco_data.errors.CorruptDatasetError: ...: global heap collection at byte ... is corrupt (...)
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path

from abco_data.errors import CorruptDatasetError

__all__ = ["check_global_heaps"]

_SIGNATURE = b"GCOL"
_SUPERBLOCK = b"\x89HDF\r\n\x1a\n"
# (path, size, mtime, inode) of files already checked in this process.
_CHECKED: dict[tuple[str, int, int, int], None] = {}
_CHECKED_MAX = 256


def _superblock_sizes(data: mmap.mmap | bytes) -> tuple[int, int, int]:
    """``(base address, size of offsets, size of lengths)`` of the superblock (HDF5's
    defaults, ``(0, 8, 8)``, when none is found)."""
    at = 0
    while at + 16 <= len(data):  # the superblock sits at 0, 512, 1024, 2048, ...
        if data[at : at + 8] == _SUPERBLOCK:
            version = data[at + 8]
            sizes = (data[at + 13], data[at + 14]) if version in (0, 1) else \
                (data[at + 9], data[at + 10])
            return at, *sizes
        at = 512 if at == 0 else 2 * at
    return 0, 8, 8


def _u(data: mmap.mmap | bytes, at: int, size: int) -> int:
    return int.from_bytes(data[at : at + size], "little")


def _walk(data: mmap.mmap | bytes, start: int, lengths: int) -> dict[int, int] | str:
    """The object sizes (by index) of the collection at ``start``, or why HDF5 would loop on
    it or read past it."""
    header = 8 + lengths
    collection = _u(data, start + 8, lengths)
    end = start + collection
    if collection < 2 * header or end > len(data):
        return f"collection size {collection}"
    objects: dict[int, int] = {}
    p = start + header
    while p < end:
        if p + header > end:  # too small for an object: HDF5 takes it as free space
            break
        index, size = _u(data, p, 2), _u(data, p + 8, lengths)
        need = header + (size + 7) // 8 * 8 if index > 0 else size
        if need == 0:
            return f"an object of size 0 at byte {p}"
        if need > end - p:
            return f"an object at byte {p} runs {need - (end - p)} bytes past the collection"
        if index > 0:
            objects[index] = size
        p += need
    return objects


def _check_references(data: mmap.mmap | bytes, address: int, objects: dict[int, int],
                      offsets: int) -> str | None:
    """Why a stored reference to an object of the collection at file address ``address``
    would make HDF5 allocate more than the object holds, or None."""
    needle = address.to_bytes(offsets, "little")
    at = data.find(needle, 4)
    while at >= 0:
        # Variable-length data: 4 bytes of length, then the heap id (address, 4-byte index).
        index = _u(data, at + offsets, 4)
        if index in objects:
            length = _u(data, at - 4, 4)
            if length > objects[index]:
                return (f"the variable-length value at byte {at - 4} claims {length} bytes,"
                        f" its heap object {index} holds {objects[index]}")
        at = data.find(needle, at + 1)
    return None


def check_global_heaps(path: str | os.PathLike[str]) -> None:
    """Raise if a global heap of the file at ``path`` would hang HDF5, or make it overrun or
    allocate more than the heap holds.

    Raises:
        CorruptDatasetError: A collection HDF5 would loop on or read past; names the file
            and the byte offset.
        OSError: The file cannot be read.
    """
    path = Path(path)
    info = path.stat()
    key = (str(path.resolve()), info.st_size, info.st_mtime_ns, info.st_ino)
    if key in _CHECKED or info.st_size == 0:
        return
    with open(path, "rb") as handle, \
            mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as data:
        base, offsets, lengths = _superblock_sizes(data)
        at = data.find(_SIGNATURE)
        while at >= 0:
            if at + 8 + lengths <= len(data) and data[at + 4] == 1:
                found = _walk(data, at, lengths)
                problem = found if isinstance(found, str) else \
                    _check_references(data, at - base, found, offsets)
                if problem is not None:
                    raise CorruptDatasetError(
                        f"{path}: global heap collection at byte {at} is corrupt ({problem})")
            at = data.find(_SIGNATURE, at + 1)
    if len(_CHECKED) >= _CHECKED_MAX:
        _CHECKED.clear()
    _CHECKED[key] = None
