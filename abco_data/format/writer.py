"""Writing a dataset file: :class:`DatasetWriter`, atomic, chunk by chunk, deterministic.

Columns are created on first append and grow in whole chunks, so a column's bytes depend only
on its contents. RGB ``uint8`` observations are stored palette-encoded while their frames
allow it (see :mod:`abco_data.format.palette`).
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from abco_data.errors import DatasetWriteError
from abco_data.format.files import atomic_target, check_target
from abco_data.format.palette import (
    MAX_COLOURS_4BIT,
    PaletteDecoder,
    PaletteEncoder,
    is_palette_candidate,
    pack4,
    unpack4,
)
from abco_data.format.schema import (
    GZIP_LEVEL,
    IMAGE_GZIP_LEVEL,
    OBSERVATIONS,
    PALETTE,
    REWARDS,
    TERMINATIONS,
    TRUNCATIONS,
    chunk_rows,
    episode_column,
)

__all__ = ["DatasetWriter"]


class _Column:
    """A resizable, chunked, gzip-compressed dataset written a whole chunk at a time.

    With ``palette`` (RGB ``uint8`` frames), rows are stored as palette indices (see
    :mod:`abco_data.format.palette`): packed two per byte (``palette4``) while the frames have at
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
                self._rewrite(self.encoder, "raw")
            else:
                if self.encoding == "palette4" and len(self.encoder) > MAX_COLOURS_4BIT:
                    self._rewrite(self.encoder, "palette")
                block = pack4(indices) if self.encoding == "palette4" else indices
        start = self.size
        self.ds.resize((start + len(block), *self.ds.shape[1:]))
        self.ds[start:] = block
        self.size += len(block)

    def _rewrite(self, encoder: PaletteEncoder, encoding: str) -> None:
        """Rewrite the rows written so far in ``encoding`` (the palette outgrew the old one)."""
        data = self.ds[: self.size]
        if self.encoding == "palette4":
            data = unpack4(data)
        if encoding == "raw":
            data = PaletteDecoder(encoder.palette).decode(data)
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



class DatasetWriter:
    """Writes one dataset file atomically: built in memory, then written to a temporary file
    next to the target and moved onto it with ``os.replace``.

    Use as a context manager. Columns are created on first append and grow in whole chunks,
    so a column's bytes depend only on its contents. An ``observations`` column of RGB
    ``uint8`` frames is stored palette-encoded (with an ``observation_palette`` dataset) while
    its frames have at most 256 colours (indices packed two per byte up to 16 colours); the
    root attribute ``observation_encoding`` says which (``"palette4"``, ``"palette"`` or
    ``"raw"``). Nothing reaches ``path`` unless the block
    exits normally; on any error the temp file is removed and ``path`` is left untouched. A
    full disk (or any ``OSError``) surfaces as :class:`~abco_data.errors.DatasetWriteError`; a
    ``path`` that is not a new path or a regular file (a device, a FIFO, a folder, a symbolic
    link) as :class:`~abco_data.errors.InvalidTargetError`, when the block starts.

    Args:
        path: The target file.

    Example:
        >>> import tempfile, os, numpy as np, h5py
        >>> target = os.path.join(tempfile.mkdtemp(), "x.hdf5")
        >>> with DatasetWriter(target) as w:
        ...     w.append("rewards", np.zeros(3))
        ...     w.attrs["format"] = "abco-dataset"
        >>> with h5py.File(target) as f:
        ...     f["rewards"].shape, f.attrs["format"]
        ((3,), 'abco-dataset')
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.attrs: dict[str, Any] = {}
        self._columns: dict[str, _Column] = {}

    def __enter__(self) -> DatasetWriter:
        check_target(self.path)  # a device, FIFO, folder or link: refused before any work
        # The file is built in memory and written out in one piece at the end: HDF5 never
        # writes to disk, so a full disk is an OSError of a plain write (no HDF5 file left
        # half-closed, which h5py would later close again from the garbage collector).
        in_memory_name = f"{self.path.name}.{id(self):x}"  # unique among open HDF5 files
        self.file = h5py.File(in_memory_name, "w", driver="core", backing_store=False,
                              libver="earliest", track_order=False)
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
        return self.file.require_group(parent), leaf

    def append(self, name: str, rows: np.ndarray) -> None:
        """Append rows to column ``name`` (``"group/name"`` for a column in a group)."""
        rows = np.asarray(rows)
        if name not in self._columns:
            group, leaf = self._group(name)
            palette = name == OBSERVATIONS and is_palette_candidate(rows.shape[1:], rows.dtype)
            self._columns[name] = _Column(group, leaf, rows.shape[1:], rows.dtype, palette)
        self._columns[name].append(rows)

    def append_steps(self, actions_name: str, observations: Any, actions: Any, rewards: Any,
                     terminations: Any, truncations: Any) -> None:  # fmt: skip
        """Append one episode's step columns, each in its schema dtype (``actions_name``:
        the kind's action column)."""
        self.append(OBSERVATIONS, observations)
        self.append(actions_name, np.asarray(actions, dtype=np.int64))
        self.append(REWARDS, np.asarray(rewards, dtype=np.float64))
        self.append(TERMINATIONS, np.asarray(terminations, dtype=bool))
        self.append(TRUNCATIONS, np.asarray(truncations, dtype=bool))

    def append_episode_index(self, lengths: Any, seeds: Any, returns: Any) -> int:
        """Append the episodes' columns (offsets, length, seed, return) of episodes of
        ``lengths`` transitions; the number of transitions."""
        length = np.asarray(lengths, dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(length)[:-1]]).astype(np.int64)
        # an episode of n transitions has n + 1 observations
        self.append(episode_column("obs_offset"), starts + np.arange(len(length)))
        self.append(episode_column("transition_offset"), starts)
        self.append(episode_column("length"), length)
        self.append(episode_column("seed"), np.asarray(seeds, dtype=np.int64))
        self.append(episode_column("return"), np.asarray(returns, dtype=np.float64))
        return int(length.sum())

    def write(self, name: str, data: np.ndarray) -> None:
        """Write a whole small array (uncompressed) as dataset ``name``."""
        group, leaf = self._group(name)
        data = np.asarray(data)
        if data.dtype.kind == "U":
            data = data.astype(h5py.string_dtype())
        group.create_dataset(leaf, data=data, track_times=False)

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        image = None
        try:
            if exc_type is None:
                self._finish()
                self.file.flush()
                image = self.file.id.get_file_image()
        except OSError as err:
            raise self._write_error(err) from err
        finally:
            self.file.close()  # in memory: closing writes nothing to disk
        if image is None:  # the block raised
            if isinstance(exc, OSError) and not isinstance(exc, DatasetWriteError):
                raise self._write_error(exc) from exc
            return
        try:
            with atomic_target(self.path, "writing") as tmp, open(tmp, "xb") as out:
                out.write(image)
        except OSError as err:
            raise self._write_error(err) from err

    def _finish(self) -> None:
        """Flush the columns' last rows, the palette and the root attributes (sorted)."""
        for column in self._columns.values():
            column.flush(final=True)
        obs = self._columns.get(OBSERVATIONS)
        if obs is not None:
            self.attrs["observation_encoding"] = obs.encoding
            if obs.encoder is not None:  # not "raw"
                self.write(PALETTE, obs.encoder.palette)
        for key in sorted(self.attrs):
            self.file.attrs[key] = self.attrs[key]
