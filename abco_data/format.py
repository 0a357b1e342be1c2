"""The on-disk format: one HDF5 file per dataset, flat columns plus episode offsets.

This module is the only place that knows the layout described in ``docs/format.md``: the
names of the columns and attributes, the compression of each column, the JSON encoding of
spaces, the atomic writer and the header checks a reader runs before trusting a file.

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
    "reference_expert_mean", "reference_random_mean",
)
#: Flat columns every file carries (``actions`` or ``idm_eval_actions`` depends on the kind).
FLAT_COLUMNS = ("observations", "rewards", "terminations", "truncations")
#: Per-episode columns under the ``episodes`` group.
EPISODE_COLUMNS = ("obs_offset", "transition_offset", "length", "seed", "return")
#: Gzip level of every column (measured in docs/format.md: level 6 halves level 1's size).
GZIP_LEVEL = 6
#: Frames per chunk of an image column; other columns use ``VECTOR_CHUNK_BYTES`` chunks.
IMAGE_CHUNK_ROWS = 32
VECTOR_CHUNK_BYTES = 1 << 16


def chunk_rows(row_shape: tuple[int, ...], dtype: Any) -> int:
    """Rows per chunk of a column whose rows have ``row_shape``.

    Example:
        >>> chunk_rows((64, 64, 3), "uint8"), chunk_rows((4,), "float32"), chunk_rows((), bool)
        (32, 4096, 65536)
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
    """A resizable, chunked, gzip-compressed dataset written a whole chunk at a time."""

    def __init__(self, group: h5py.Group, name: str, row_shape: tuple[int, ...], dtype: Any):
        self.rows = chunk_rows(row_shape, dtype)
        self.ds = group.create_dataset(
            name, shape=(0, *row_shape), maxshape=(None, *row_shape), dtype=dtype,
            chunks=(self.rows, *row_shape), compression="gzip", compression_opts=GZIP_LEVEL,
            track_times=False,
        )
        self.pending: list[np.ndarray] = []
        self.pending_rows = 0
        self.size = 0

    def append(self, rows: np.ndarray) -> None:
        if len(rows):
            self.pending.append(np.asarray(rows, dtype=self.ds.dtype))
            self.pending_rows += len(rows)
        if self.pending_rows >= 8 * self.rows:
            self.flush(final=False)

    def flush(self, final: bool) -> None:
        if not self.pending_rows:
            return
        block = np.concatenate(self.pending)
        keep = len(block) if final else len(block) - len(block) % self.rows
        start = self.size
        self.ds.resize((start + keep, *self.ds.shape[1:]))
        self.ds[start : start + keep] = block[:keep]
        self.size += keep
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


class DatasetWriter:
    """Writes one dataset file atomically: a temp file next to the target, then ``os.replace``.

    Use as a context manager. Columns are created on first append and grow in whole chunks,
    so a column's bytes depend only on its contents. Nothing reaches ``path`` unless the block
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
            self._columns[name] = _Column(group, leaf, rows.shape[1:], rows.dtype)
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
    if attrs["kind"] not in KINDS:
        raise CorruptDatasetError(f"{path}: unknown kind {attrs['kind']!r}; expected {KINDS}")
    action_col = "actions" if attrs["kind"] == "pre_demonstrations" else "idm_eval_actions"
    wanted = [*FLAT_COLUMNS, action_col, *(f"episodes/{c}" for c in EPISODE_COLUMNS)]
    absent = [c for c in wanted if c not in f]
    if absent:
        raise CorruptDatasetError(f"{path}: missing column(s) {', '.join(absent)}")
    return attrs
