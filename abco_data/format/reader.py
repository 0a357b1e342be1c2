"""Reading a dataset file: :func:`open_h5` and column readers.

:class:`ObservationReader` decodes palette-encoded observations transparently; the lazy
per-process handle that reads them is :class:`abco_data.format.handle.LazyH5File`.

Every file is checked by :func:`~abco_data.format.heaps.check_global_heaps` before HDF5 opens
it, and every HDF5 error met while reading (``OSError``, ``RuntimeError``, ``KeyError``)
becomes a :class:`~abco_data.errors.CorruptDatasetError` that names the file
(:func:`hdf5_errors`).
"""

from __future__ import annotations

import math
import os
import stat
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np

from abco_data.errors import CorruptDatasetError, DatasetFileNotFoundError, DatasetReadError
from abco_data.format.heaps import check_global_heaps
from abco_data.format.palette import MAX_COLOURS, PaletteDecoder
from abco_data.format.schema import OBSERVATION_ENCODINGS, OBSERVATIONS, PALETTE, attr_value

__all__ = ["HDF5_ERRORS", "open_h5", "open_h5_file", "hdf5_errors", "h5_column",
           "read_column", "read_rows", "ObservationReader"]

#: What h5py raises for a damaged file: ``OSError`` (unreadable data), ``RuntimeError``
#: (inconsistent metadata) and ``KeyError`` (an object that cannot be opened).
HDF5_ERRORS = (OSError, RuntimeError, KeyError)


@contextmanager
def hdf5_errors(path: str | os.PathLike[str], what: str = "data") -> Iterator[None]:
    """Turn HDF5's errors raised in the block into a :class:`CorruptDatasetError` naming
    ``path`` and ``what`` was being read.

    Example:
        >>> with hdf5_errors("/data/x.hdf5", "column rewards"):  # doctest: +ELLIPSIS
        ...     raise OSError("Can't synchronously read data (filter returned failure)")
        Traceback (most recent call last):
        abco_data.errors.CorruptDatasetError: /data/x.hdf5: column rewards cannot be read ...
    """
    try:
        yield
    except CorruptDatasetError:
        raise
    except HDF5_ERRORS as err:
        detail = str(err.args[0]) if isinstance(err, KeyError) and err.args else str(err)
        raise CorruptDatasetError(f"{path}: {what} cannot be read (corrupt or truncated"
                                  f" file): {detail}") from err


def h5_column(f: h5py.Group, name: str) -> h5py.Dataset:
    """``f[name]``, checked to be an HDF5 dataset (a column), not a group or a named type.

    Raises:
        KeyError: No object ``name`` (h5py's own; :func:`hdf5_errors` reports it).
        CorruptDatasetError: ``name`` is a group or a named type.
    """
    obj = f[name]
    if not isinstance(obj, h5py.Dataset):
        raise CorruptDatasetError(f"{f.file.filename}: {name} is an HDF5"
                                  f" {type(obj).__name__}, not a column")
    return obj


def read_column(ds: h5py.Dataset, out: np.ndarray) -> None:
    """Read all of ``ds`` into the preallocated ``out`` (no intermediate copy)."""
    if out.size:
        ds.read_direct(out)


def read_rows(ds: h5py.Dataset, rows: np.ndarray) -> np.ndarray:
    """Rows ``rows`` of ``ds`` (any order, repeats allowed), each needed chunk read once.

    Reads whole chunks as slices instead of one HDF5 point selection per row, which h5py
    handles slowly (1,000 random frames: about 0.16 s instead of 2 s).
    """
    rows = np.asarray(rows, dtype=np.int64)
    out = np.empty((len(rows), *ds.shape[1:]), dtype=ds.dtype)
    n = ds.chunks[0] if ds.chunks is not None else max(1, len(ds))
    chunk_of = rows // n
    for c in np.unique(chunk_of):
        block = ds[int(c) * n : (int(c) + 1) * n]
        hit = chunk_of == c
        out[hit] = block[rows[hit] - int(c) * n]
    return out


def _deflated_row_chunks(ds: h5py.Dataset) -> bool:
    """Whether ``ds`` is uint8 in chunks of whole rows compressed by deflate (gzip) alone."""
    if ds.chunks is None or ds.chunks[1:] != ds.shape[1:] or ds.dtype != np.uint8:
        return False
    plist = ds.id.get_create_plist()
    return plist.get_nfilters() == 1 and plist.get_filter(0)[0] == h5py.h5z.FILTER_DEFLATE


class ObservationReader:
    """Reads the ``observations`` column of an open file, decoding a palette transparently.

    Args:
        f: An open abco dataset file.

    Raises:
        CorruptDatasetError: An unknown ``observation_encoding`` or a malformed palette.
    """

    #: Chunks inflated (then decoded) per step of a long read.
    BLOCK_CHUNKS = 4

    def __init__(self, f: h5py.File) -> None:
        self.path = f.filename
        self.ds = h5_column(f, OBSERVATIONS)
        self.encoding = attr_value(f.attrs.get("observation_encoding", "raw"))
        self._palette: np.ndarray | None = None
        self._decoder: PaletteDecoder | None = None
        if self.encoding in ("palette", "palette4"):
            if PALETTE not in f:
                raise CorruptDatasetError(f"{f.filename}: observation_encoding is"
                                          f" {self.encoding!r} but the {PALETTE} dataset is"
                                          " missing")
            palette = h5_column(f, PALETTE)[()]
            if (palette.dtype != np.uint8 or palette.ndim != 2 or palette.shape[1] != 3
                    or len(palette) > MAX_COLOURS or self.ds.dtype != np.uint8
                    or len(np.unique(palette, axis=0)) != len(palette)):  # a colour twice
                raise CorruptDatasetError(
                    f"{f.filename}: malformed {PALETTE} {palette.shape} {palette.dtype} for"
                    f" observations of {self.ds.dtype}")
            self._palette = palette
        elif self.encoding != "raw":
            raise CorruptDatasetError(f"{f.filename}: unknown observation_encoding"
                                      f" {self.encoding!r}; expected one of"
                                      f" {OBSERVATION_ENCODINGS}")
        shape = self.ds.shape
        if self.encoding == "palette4":
            shape = (*shape[:-1], 2 * shape[-1])
        self.shape = shape if self._palette is None else (*shape, 3)
        self.dtype = np.dtype(np.uint8) if self._palette is not None else self.ds.dtype
        # The chunk shape, read once (h5py's properties cost microseconds a call).
        chunks = self.ds.chunks if self._palette is not None else None
        self._raw_chunks = chunks is not None and _deflated_row_chunks(self.ds)
        self._chunk: tuple[int, ...] = chunks if chunks is not None and self._raw_chunks else ()

    @property
    def decoder(self) -> PaletteDecoder | None:
        """The palette decoder (built on first use: its look-up table takes ~10 ms)."""
        if self._palette is not None and self._decoder is None:
            self._decoder = PaletteDecoder(self._palette, packed=self.encoding == "palette4")
        return self._decoder

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def palette(self) -> np.ndarray | None:
        """The ``(K, 3)`` palette, or None for raw observations."""
        return self._palette

    def read(self, start: int = 0, stop: int | None = None,
             out: np.ndarray | None = None) -> np.ndarray:
        """Rows ``start:stop`` decoded, into ``out`` if given (a contiguous array)."""
        stop = len(self) if stop is None else min(stop, len(self))
        start = min(start, stop)
        if out is None:
            out = np.empty((stop - start, *self.shape[1:]), dtype=self.dtype)
        if stop == start:
            return out
        with hdf5_errors(self.path, "observations"):
            return self._read(start, stop, out)

    def _read(self, start: int, stop: int, out: np.ndarray) -> np.ndarray:
        decoder = self.decoder
        if decoder is None:
            self.ds.read_direct(out, np.s_[start:stop], np.s_[0 : stop - start])
            self._check_finite(out, start)
            return out
        if not self._raw_chunks:
            self._read_decoded(decoder, start, stop, out)
            return out
        # Whole chunks inflated here, partial ones at the ends through HDF5 (and its cache).
        n = self._chunk[0]
        first = min(-(-start // n) * n, stop)
        last = stop if stop == len(self) else max(first, stop // n * n)
        self._read_decoded(decoder, start, first, out[: first - start])
        for a in range(first, last, n):
            b = min(a + n, last)
            self._chunk_decoded(decoder, a // n, out[a - start : b - start])
        self._read_decoded(decoder, last, stop, out[last - start :])
        return out

    def _read_decoded(self, decoder: PaletteDecoder, start: int, stop: int,
                      out: np.ndarray) -> None:
        """Rows ``start:stop`` read through HDF5, checked and decoded into ``out``.

        A few chunks at a time into one small buffer, decoded straight into ``out``: the only
        memory beyond ``out`` is that buffer and the decoder's ~1 MB gather buffer.
        """
        if stop <= start:
            return
        step = self.BLOCK_CHUNKS * (self.ds.chunks[0] if self.ds.chunks else stop - start)
        buf = np.empty((min(step, stop - start), *self.ds.shape[1:]), dtype=self.ds.dtype)
        for a in range(start, stop, step):
            b = min(a + step, stop)
            self.ds.read_direct(buf, np.s_[a:b], np.s_[0 : b - a])
            self._check_indices(decoder, buf[: b - a], a)
            decoder.decode_into(buf[: b - a], out[a - start : b - start])

    def _chunk_decoded(self, decoder: PaletteDecoder, c: int, out: np.ndarray) -> None:
        """The first ``len(out)`` rows of chunk ``c``, inflated here with zlib, checked and
        decoded.

        Skips HDF5's filter pipeline and chunk cache, which inflate into the cache and copy
        out (twice the time of inflating into a fresh buffer for a whole-column read). Anything
        unexpected (no storage, a skipped filter, a zlib error, a wrong size) falls back to
        HDF5, which reads it or raises the same errors as before.
        """
        n, size = self._chunk[0], math.prod(self._chunk)
        data = b""
        try:
            mask, raw = self.ds.id.read_direct_chunk((c * n, *(0 for _ in self._chunk[1:])))
            if not mask:
                data = zlib.decompress(raw, bufsize=size)
        except (RuntimeError, zlib.error):
            pass
        if len(data) != size:
            self._read_decoded(decoder, c * n, c * n + len(out), out)
            return
        stored = np.frombuffer(data, dtype=np.uint8).reshape(self._chunk)[: len(out)]
        self._check_indices(decoder, stored, c * n)
        decoder.decode_into(stored, out)

    def rows(self, rows: np.ndarray) -> np.ndarray:
        """Rows ``rows`` (any order, repeats allowed) decoded; see :func:`read_rows`."""
        with hdf5_errors(self.path, "observations"):
            block = read_rows(self.ds, rows)
        decoder = self.decoder
        if decoder is None:
            self._check_finite(block, None)
            return block
        self._check_indices(decoder, block, None)
        return decoder.decode(block)

    def _check_indices(self, decoder: PaletteDecoder, stored: np.ndarray,
                       start: int | None) -> None:
        """Every palette index of ``stored`` names a palette entry.

        Two max-reductions over the nibbles (or one over the bytes): several times faster than
        a table look-up of every byte, which took a third of a whole-column read.
        """
        if not stored.size:
            return
        colours = len(decoder.palette)
        if self.encoding == "palette4":
            top = max(int((stored & 15).max()), int((stored >> 4).max()))
        else:
            top = int(stored.max())
        if top >= colours:
            where = "" if start is None else f" {start}..{start + len(stored) - 1}"
            raise CorruptDatasetError(
                f"{self.path}: observations{where} hold palette indices beyond the"
                f" {colours} entries of {PALETTE}")

    def _check_finite(self, values: np.ndarray, start: int | None) -> None:
        if values.dtype.kind == "f" and not np.isfinite(values).all():
            where = "" if start is None else f" {start}..{start + len(values) - 1}"
            raise CorruptDatasetError(f"{self.path}: observations{where} hold NaN or"
                                      " infinite values")

    def __getitem__(self, key: slice) -> np.ndarray:
        start, stop, stride = key.indices(len(self))
        if stride != 1:
            raise IndexError("observations: only contiguous slices are supported")
        return self.read(start, stop)



def open_h5_file(path: str | os.PathLike[str]) -> h5py.File:
    """Open ``path`` read-only after checking it (see :func:`open_h5`); the caller closes it."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError as err:
        raise DatasetFileNotFoundError(f"{path}: no such dataset file") from err
    except OSError as err:
        raise DatasetReadError(f"{path}: cannot read the dataset file: {err.strerror}") from err
    if not stat.S_ISREG(mode):
        raise DatasetReadError(f"{path}: not a regular file")
    try:
        check_global_heaps(path)
        return h5py.File(path, "r")
    except PermissionError as err:
        raise DatasetReadError(f"{path}: cannot read the dataset file: {err.strerror}") from err
    except HDF5_ERRORS as err:
        raise CorruptDatasetError(
            f"{path}: not a readable HDF5 file (truncated or corrupt): {err}") from err


@contextmanager
def open_h5(path: str | os.PathLike[str]) -> Iterator[h5py.File]:
    """Open ``path`` read-only; HDF5's errors become errors that name the file.

    Raises:
        DatasetFileNotFoundError: No file at ``path``.
        DatasetReadError: Not a regular file, or no permission to read it.
        CorruptDatasetError: Not an HDF5 file, truncated, or damaged.
    """
    f = open_h5_file(path)
    try:
        yield f
    finally:
        f.close()
