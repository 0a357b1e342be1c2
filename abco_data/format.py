"""The on-disk format: one HDF5 file per dataset, flat columns plus episode offsets.

This module is the only place that knows the layout described in ``docs/format.md``: the
names of the columns and attributes, the compression of each column, the JSON encoding of
spaces, the atomic writer and the header checks a reader runs before trusting a file. The
palette encoding of image observations is in :mod:`abco_data.palette`; here the writer picks
it and :class:`ObservationReader` decodes it.

Example:
    >>> from gymnasium import spaces
    >>> space = space_from_json(space_to_json(spaces.Discrete(4)))
    >>> space
    Discrete(4)
"""

from __future__ import annotations

import errno
import json
import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from gymnasium import spaces

from abco_data.errors import CorruptDatasetError, DatasetWriteError, FormatVersionError
from abco_data.palette import (
    MAX_COLOURS,
    MAX_COLOURS_4BIT,
    PaletteDecoder,
    PaletteEncoder,
    is_palette_candidate,
    pack4,
    unpack4,
)

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "KINDS",
    "REQUIRED_ROOT_ATTRS",
    "DatasetWriter",
    "open_h5",
    "check_header",
    "space_to_json",
    "space_from_json",
    "chunk_rows",
    "to_json",
    "read_column",
    "read_rows",
    "ObservationReader",
]

#: The ``format`` root attribute of every abco dataset file.
FORMAT_NAME = "abco-dataset"
#: The ``format_version`` this package writes and reads (independent of the package version).
FORMAT_VERSION = 1
#: Dataset kinds, as stored in the ``kind`` root attribute.
KINDS = ("expert", "pre_demonstrations")
#: Root attributes every file carries.
REQUIRED_ROOT_ATTRS = (
    "format", "format_version", "dataset_id", "kind", "env_id", "env_spec", "env_kwargs",
    "observation_space", "action_space", "generator", "generator_version", "seed",
    "num_episodes", "num_transitions", "num_observations", "creation_params",
    "reference_expert_mean", "reference_random_mean", "observation_encoding",
)
#: Values of the ``observation_encoding`` root attribute.
OBSERVATION_ENCODINGS = ("raw", "palette", "palette4")
#: Flat columns every file carries (``actions`` or ``idm_eval_actions`` depends on the kind).
FLAT_COLUMNS = ("observations", "rewards", "terminations", "truncations")
#: Per-episode columns under the ``episodes`` group.
EPISODE_COLUMNS = ("obs_offset", "transition_offset", "length", "seed", "return")
#: Gzip level of vector columns (small; level 6 halves level 1's size).
GZIP_LEVEL = 6
#: Gzip level of image-like columns (rows of 2+ dimensions), measured in docs/format.md: on
#: packed palette indices level 3 is 2.4x smaller than level 1, as fast to write, and
#: inflates fastest; level 6 is a third smaller but writes twice as slowly.
IMAGE_GZIP_LEVEL = 3
#: Rows per chunk of an image-like column; other columns use ``VECTOR_CHUNK_BYTES`` chunks.
IMAGE_CHUNK_ROWS = 64
VECTOR_CHUNK_BYTES = 1 << 16
#: The column stored palette-encoded when its frames allow it, and its palette.
OBSERVATIONS = "observations"
PALETTE = "observation_palette"


def chunk_rows(row_shape: tuple[int, ...], dtype: Any) -> int:
    """Rows per chunk of a column whose rows have ``row_shape``.

    Example:
        >>> chunk_rows((64, 64, 3), "uint8"), chunk_rows((4,), "float32"), chunk_rows((), bool)
        (64, 4096, 65536)
    """
    if len(row_shape) >= 2:
        return IMAGE_CHUNK_ROWS
    row_bytes = int(np.prod(row_shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    return max(1, VECTOR_CHUNK_BYTES // max(1, row_bytes))


def to_json(value: Any) -> str:
    """Canonical JSON (sorted keys, no spaces) of plain data; non-finite floats as strings."""

    def clean(v: Any) -> Any:
        if isinstance(v, dict):
            return {str(k): clean(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [clean(x) for x in v]
        if isinstance(v, np.ndarray):
            return clean(v.tolist())
        if isinstance(v, (np.integer,)):
            return int(v)
        if isinstance(v, (float, np.floating)):
            f = float(v)
            return f if np.isfinite(f) else str(f)
        return v

    return json.dumps(clean(value), sort_keys=True, separators=(",", ":"))


def _floats(v: Any) -> Any:
    return float(v) if isinstance(v, str) else v


def space_to_json(space: spaces.Space[Any]) -> str:
    """JSON of a ``Box`` or ``Discrete`` space (uniform bounds collapse to one number)."""
    if isinstance(space, spaces.Discrete):
        return to_json({"type": "Discrete", "n": int(space.n), "start": int(space.start)})
    if isinstance(space, spaces.Box):
        low, high = space.low, space.high
        return to_json({
            "type": "Box", "shape": list(space.shape), "dtype": str(space.dtype),
            "low": low.flat[0] if np.all(low == low.flat[0]) else low,
            "high": high.flat[0] if np.all(high == high.flat[0]) else high,
        })
    raise TypeError(f"abco datasets store Box or Discrete spaces, not {space}")


def space_from_json(text: str) -> spaces.Space[Any]:
    """Inverse of :func:`space_to_json`."""
    d = json.loads(text)
    if d["type"] == "Discrete":
        return spaces.Discrete(d["n"], start=d["start"])
    dtype = np.dtype(d["dtype"])
    low = np.asarray(_floats(d["low"]) if not isinstance(d["low"], list)
                     else [_floats(x) for x in d["low"]])
    high = np.asarray(_floats(d["high"]) if not isinstance(d["high"], list)
                      else [_floats(x) for x in d["high"]])
    low, high = low.astype(dtype), high.astype(dtype)
    return spaces.Box(low.item() if low.ndim == 0 else low, high.item() if high.ndim == 0
                      else high, shape=tuple(d["shape"]), dtype=dtype)


class _Column:
    """A resizable, chunked, gzip-compressed dataset written a whole chunk at a time.

    With ``palette`` (RGB ``uint8`` frames), rows are stored as palette indices (see
    :mod:`abco_data.palette`): packed two per byte (``palette4``) while the frames have at
    most 16 colours and an even width, one per byte (``palette``) up to 256 colours, raw
    beyond; on a change the rows already written are rewritten in the new encoding.
    """

    def __init__(self, group: h5py.Group, name: str, row_shape: tuple[int, ...], dtype: Any,
                 palette: bool = False):
        self.group, self.name, self.row_shape = group, name, tuple(row_shape)
        self.dtype = np.dtype(dtype)
        self.rows = chunk_rows(row_shape, dtype)
        self.encoder = PaletteEncoder() if palette else None
        self.encoding = "raw"
        if palette:
            self.encoding = "palette4" if self.row_shape[1] % 2 == 0 else "palette"
        self.ds = self._create()
        self.pending: list[np.ndarray] = []
        self.pending_rows = 0
        self.size = 0

    def _create(self) -> h5py.Dataset:
        shape = self.row_shape
        if self.encoding == "palette":
            shape = shape[:-1]
        elif self.encoding == "palette4":
            shape = (shape[0], shape[1] // 2)
        level = IMAGE_GZIP_LEVEL if len(self.row_shape) >= 2 else GZIP_LEVEL
        return self.group.create_dataset(
            self.name, shape=(0, *shape), maxshape=(None, *shape), dtype=self.dtype,
            chunks=(self.rows, *shape), compression="gzip", compression_opts=level,
            track_times=False,
        )

    def append(self, rows: np.ndarray) -> None:
        if len(rows):
            self.pending.append(np.asarray(rows, dtype=self.dtype))
            self.pending_rows += len(rows)
        if self.pending_rows >= 8 * self.rows:
            self.flush(final=False)

    def _store(self, block: np.ndarray) -> None:
        if self.encoder is not None:
            indices = self.encoder.encode(block)
            if indices is None:
                self._rewrite("raw")
            else:
                if self.encoding == "palette4" and len(self.encoder) > MAX_COLOURS_4BIT:
                    self._rewrite("palette")
                block = pack4(indices) if self.encoding == "palette4" else indices
        start = self.size
        self.ds.resize((start + len(block), *self.ds.shape[1:]))
        self.ds[start:] = block
        self.size += len(block)

    def _rewrite(self, encoding: str) -> None:
        """Rewrite the rows written so far in ``encoding`` (the palette outgrew the old one)."""
        data = self.ds[: self.size]
        if self.encoding == "palette4":
            data = unpack4(data)
        if encoding == "raw":
            data = PaletteDecoder(self.encoder.palette).decode(data)
            self.encoder = None
        del self.group[self.name]
        self.encoding = encoding
        self.ds = self._create()
        self.ds.resize((self.size, *self.ds.shape[1:]))
        if self.size:
            self.ds[:] = data

    def flush(self, final: bool) -> None:
        if not self.pending_rows:
            return
        block = np.concatenate(self.pending)
        keep = len(block) if final else len(block) - len(block) % self.rows
        self._store(block[:keep])
        rest = block[keep:]
        self.pending, self.pending_rows = ([rest] if len(rest) else []), len(rest)


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
        self.ds = f[OBSERVATIONS]
        self.encoding = _attr(f.attrs.get("observation_encoding", "raw"))
        self.decoder: PaletteDecoder | None = None
        if self.encoding in ("palette", "palette4"):
            if PALETTE not in f:
                raise CorruptDatasetError(f"{f.filename}: observation_encoding is"
                                          f" {self.encoding!r} but the {PALETTE} dataset is"
                                          " missing")
            palette = f[PALETTE][()]
            if (palette.dtype != np.uint8 or palette.ndim != 2 or palette.shape[1] != 3
                    or len(palette) > MAX_COLOURS or self.ds.dtype != np.uint8):
                raise CorruptDatasetError(
                    f"{f.filename}: malformed {PALETTE} {palette.shape} {palette.dtype} for"
                    f" observations of {self.ds.dtype}")
            self.decoder = PaletteDecoder(palette, packed=self.encoding == "palette4")
        elif self.encoding != "raw":
            raise CorruptDatasetError(f"{f.filename}: unknown observation_encoding"
                                      f" {self.encoding!r}; expected one of"
                                      f" {OBSERVATION_ENCODINGS}")
        self.shape = self.ds.shape if self.decoder is None else \
            self.decoder.out_shape(self.ds.shape)
        self.dtype = np.dtype(np.uint8) if self.decoder is not None else self.ds.dtype

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def palette(self) -> np.ndarray | None:
        """The ``(K, 3)`` palette, or None for raw observations."""
        return None if self.decoder is None else self.decoder.palette

    def read(self, start: int = 0, stop: int | None = None,
             out: np.ndarray | None = None) -> np.ndarray:
        """Rows ``start:stop`` decoded, into ``out`` if given (a contiguous array)."""
        stop = len(self) if stop is None else min(stop, len(self))
        start = min(start, stop)
        if out is None:
            out = np.empty((stop - start, *self.shape[1:]), dtype=self.dtype)
        if stop == start:
            return out
        if self.decoder is None:
            self.ds.read_direct(out, np.s_[start:stop], np.s_[0 : stop - start])
            return out
        # A few chunks at a time into one small buffer, decoded straight into ``out``: the
        # only memory beyond ``out`` is that buffer and the decoder's ~1 MB gather buffer.
        step = self.BLOCK_CHUNKS * (self.ds.chunks[0] if self.ds.chunks else stop - start)
        buf = np.empty((min(step, stop - start), *self.ds.shape[1:]), dtype=self.ds.dtype)
        for a in range(start, stop, step):
            b = min(a + step, stop)
            self.ds.read_direct(buf, np.s_[a:b], np.s_[0 : b - a])
            self.decoder.decode_into(buf[: b - a], out[a - start : b - start])
        return out

    def rows(self, rows: np.ndarray) -> np.ndarray:
        """Rows ``rows`` (any order, repeats allowed) decoded; see :func:`read_rows`."""
        block = read_rows(self.ds, rows)
        return block if self.decoder is None else self.decoder.decode(block)

    def __getitem__(self, key: slice) -> np.ndarray:
        start, stop, stride = key.indices(len(self))
        if stride != 1:
            raise IndexError("observations: only contiguous slices are supported")
        return self.read(start, stop)


class DatasetWriter:
    """Writes one dataset file atomically: a temp file next to the target, then ``os.replace``.

    Use as a context manager. Columns are created on first append and grow in whole chunks,
    so a column's bytes depend only on its contents. An ``observations`` column of RGB
    ``uint8`` frames is stored palette-encoded (with an ``observation_palette`` dataset) while
    its frames have at most 256 colours (indices packed two per byte up to 16 colours); the
    root attribute ``observation_encoding`` says which (``"palette4"``, ``"palette"`` or
    ``"raw"``). Nothing reaches ``path`` unless the block
    exits normally; on any error the temp file is removed and ``path`` is left untouched. A
    full disk (or any ``OSError``) surfaces as :class:`~abco_data.errors.DatasetWriteError`.

    Args:
        path: The target file.

    Example:
        >>> import tempfile, os, numpy as np, h5py
        >>> target = os.path.join(tempfile.mkdtemp(), "x.hdf5")
        >>> with DatasetWriter(target) as w:
        ...     w.append("rewards", np.zeros(3))
        ...     w.attrs["format"] = FORMAT_NAME
        >>> with h5py.File(target) as f:
        ...     f["rewards"].shape, f.attrs["format"]
        ((3,), 'abco-dataset')
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.attrs: dict[str, Any] = {}
        self._columns: dict[str, _Column] = {}

    def __enter__(self) -> DatasetWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # A hidden, unique name in the target's folder (same file system: os.replace is
        # atomic); h5py creates it, so the final file gets the umask's usual permissions.
        self.tmp = self.path.with_name(f".{self.path.name}.{uuid.uuid4().hex}.tmp")
        try:
            self.file = h5py.File(self.tmp, "w-", libver="earliest", track_order=False)
        except OSError as err:
            self.tmp.unlink(missing_ok=True)
            raise self._write_error(err) from err
        return self

    def _write_error(self, err: OSError) -> DatasetWriteError:
        what = "no space left on device" if err.errno == errno.ENOSPC else str(err)
        return DatasetWriteError(
            err.errno or errno.EIO, f"could not write dataset {self.path}: {what};"
            " the target was left unchanged", str(self.path))

    def _group(self, name: str) -> tuple[h5py.Group, str]:
        if "/" not in name:
            return self.file, name
        parent, leaf = name.rsplit("/", 1)
        group = self.file[parent] if parent in self.file else self.file.create_group(parent)
        return group, leaf

    def append(self, name: str, rows: np.ndarray) -> None:
        """Append rows to column ``name`` (``"group/name"`` for a column in a group)."""
        rows = np.asarray(rows)
        if name not in self._columns:
            group, leaf = self._group(name)
            palette = name == OBSERVATIONS and is_palette_candidate(rows.shape[1:], rows.dtype)
            self._columns[name] = _Column(group, leaf, rows.shape[1:], rows.dtype, palette)
        self._columns[name].append(rows)

    def write(self, name: str, data: np.ndarray) -> None:
        """Write a whole small array (uncompressed) as dataset ``name``."""
        group, leaf = self._group(name)
        data = np.asarray(data)
        if data.dtype.kind == "U":
            data = data.astype(h5py.string_dtype())
        group.create_dataset(leaf, data=data, track_times=False)

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        try:
            if exc_type is None:
                for column in self._columns.values():
                    column.flush(final=True)
                obs = self._columns.get(OBSERVATIONS)
                if obs is not None:
                    self.attrs["observation_encoding"] = obs.encoding
                    if obs.encoding != "raw":
                        self.write(PALETTE, obs.encoder.palette)
                for key in sorted(self.attrs):
                    self.file.attrs[key] = self.attrs[key]
            self.file.close()
            if exc_type is None:
                with open(self.tmp, "rb+") as fh:
                    os.fsync(fh.fileno())
                os.replace(self.tmp, self.path)
        except OSError as err:
            self.tmp.unlink(missing_ok=True)
            raise self._write_error(err) from err
        except BaseException:
            self.tmp.unlink(missing_ok=True)
            raise
        finally:
            if exc_type is not None:
                self.tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError) and not isinstance(exc, DatasetWriteError):
            raise self._write_error(exc) from exc


@contextmanager
def open_h5(path: str | os.PathLike[str]) -> Iterator[h5py.File]:
    """Open ``path`` read-only, turning HDF5's errors into ones that name the file.

    Raises:
        FileNotFoundError: No file at ``path``.
        CorruptDatasetError: Not an HDF5 file, or truncated.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(errno.ENOENT, "no dataset file", str(path))
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise CorruptDatasetError(
            f"{path}: not a readable HDF5 file (truncated or corrupt): {err}") from err
    try:
        yield f
    finally:
        f.close()


def _attr(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def check_header(f: h5py.File, path: str | os.PathLike[str]) -> dict[str, Any]:
    """Check the format name, version, kind and columns; return the root attributes.

    Raises:
        CorruptDatasetError: Not an abco dataset, or a required attribute or column is missing.
        FormatVersionError: A ``format_version`` other than :data:`FORMAT_VERSION`.
    """
    attrs = {k: _attr(v) for k, v in f.attrs.items()}
    if attrs.get("format") != FORMAT_NAME:
        raise CorruptDatasetError(
            f"{path}: not an abco dataset (root attribute 'format' is"
            f" {attrs.get('format')!r}, expected {FORMAT_NAME!r})")
    if attrs.get("format_version") != FORMAT_VERSION:
        raise FormatVersionError(
            f"{path}: format_version {attrs.get('format_version')!r} is not supported by this"
            f" abco (it reads format_version {FORMAT_VERSION}); regenerate or download the file")
    missing = [k for k in REQUIRED_ROOT_ATTRS if k not in attrs]
    if missing:
        raise CorruptDatasetError(f"{path}: missing root attribute(s) {', '.join(missing)}")
    if attrs["observation_encoding"] not in OBSERVATION_ENCODINGS:
        raise CorruptDatasetError(f"{path}: unknown observation_encoding"
                                  f" {attrs['observation_encoding']!r}; expected one of"
                                  f" {OBSERVATION_ENCODINGS}")
    if attrs["observation_encoding"] != "raw" and PALETTE not in f:
        raise CorruptDatasetError(f"{path}: observation_encoding is"
                                  f" {attrs['observation_encoding']!r} but the {PALETTE}"
                                  " dataset is missing")
    if attrs["kind"] not in KINDS:
        raise CorruptDatasetError(f"{path}: unknown kind {attrs['kind']!r}; expected {KINDS}")
    action_col = "actions" if attrs["kind"] == "pre_demonstrations" else "idm_eval_actions"
    wanted = [*FLAT_COLUMNS, action_col, *(f"episodes/{c}" for c in EPISODE_COLUMNS)]
    absent = [c for c in wanted if c not in f]
    if absent:
        raise CorruptDatasetError(f"{path}: missing column(s) {', '.join(absent)}")
    return attrs
