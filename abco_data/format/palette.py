"""Lossless palette encoding of RGB image columns (``observation_encoding = "palette"``).

A column of ``uint8`` RGB frames ``(rows, H, W, 3)`` with at most 256 distinct colours is
stored as ``(rows, H, W)`` ``uint8`` indices into a ``(K, 3)`` ``uint8`` palette; a plain
h5py reader decodes it with ``palette[indices]``. The maze frames have 5 colours, so this
stores and compresses a third of the bytes, which is what makes writing and reading fast.

Palette entries are in order of first appearance in the column (pixels in C order), so
the palette, like the rest of the file, depends only on the column's contents.

Decoding here avoids numpy's slow 3-byte gather: pairs of indices, read as one ``uint16``,
look up 8-byte entries of a 65,536-entry table holding the two pixels' 6 bytes, stored with
a 6-byte stride (each store's 2 spare bytes are overwritten by the next one).

Example:
    >>> frames = np.zeros((2, 4, 4, 3), np.uint8); frames[1, 2, 3] = (200, 0, 0)
    >>> enc = PaletteEncoder()
    >>> idx = enc.encode(frames)
    >>> enc.palette.tolist(), idx[1, 2, 3]
    ([[0, 0, 0], [200, 0, 0]], np.uint8(1))
    >>> out = np.empty_like(frames)
    >>> PaletteDecoder(enc.palette).decode_into(idx, out)
    >>> np.array_equal(out, frames)
    True
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["MAX_COLOURS", "MAX_COLOURS_4BIT", "PaletteEncoder", "PaletteDecoder",
           "is_palette_candidate", "pack4", "unpack4"]

#: Largest palette (indices are ``uint8``).
MAX_COLOURS = 256
#: Largest palette whose indices are packed two per byte (``palette4``).
MAX_COLOURS_4BIT = 16
_UNKNOWN = 255  # index the encoder's look-up table gives colours not (yet) in the palette


def pack4(indices: np.ndarray) -> np.ndarray:
    """Two 4-bit indices per byte along the last (even) axis, the first in the low nibble.

    Example:
        >>> pack4(np.array([[1, 2, 15, 0]], np.uint8)).tolist(), unpack4(np.array([[33, 15]],
        ...     np.uint8)).tolist()
        ([[33, 15]], [[1, 2, 15, 0]])
    """
    indices = np.ascontiguousarray(indices, dtype=np.uint8)
    flat = indices.reshape(-1)  # an even last axis: pairs never cross rows
    packed = flat[1::2] << 4
    packed |= flat[0::2]
    return packed.reshape(*indices.shape[:-1], indices.shape[-1] // 2)


def unpack4(packed: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack4`: ``(..., w)`` bytes -> ``(..., 2 * w)`` indices."""
    packed = np.asarray(packed, dtype=np.uint8)
    shape = (*packed.shape[:-1], 2 * packed.shape[-1]) if packed.ndim else (2,)
    return np.stack([packed & 15, packed >> 4], axis=-1).reshape(shape)


def is_palette_candidate(row_shape: tuple[int, ...], dtype: np.dtype) -> bool:
    """Whether rows of ``row_shape`` and ``dtype`` are RGB frames ``(H, W, 3)`` of uint8."""
    return np.dtype(dtype) == np.uint8 and len(row_shape) == 3 and row_shape[-1] == 3


def _pixel_codes(frames: np.ndarray) -> np.ndarray:
    """``r | g << 8 | b << 16`` (uint32) of every pixel of contiguous ``(..., 3)`` uint8."""
    flat = frames.reshape(-1)
    n = flat.size // 3
    codes = np.empty(n, dtype=np.uint32)
    if n > 1:
        # Unaligned little-endian 4-byte reads at a 3-byte stride: r, g, b and the next r.
        words = np.ndarray((n - 1,), dtype="<u4", buffer=flat, strides=(3,))
        np.bitwise_and(words, 0xFFFFFF, out=codes[:-1])
    if n:
        r, g, b = (int(v) for v in flat[-3:])
        codes[-1] = r | g << 8 | b << 16
    return codes


class PaletteEncoder:
    """Maps RGB frames to palette indices, growing the palette in first-appearance order."""

    def __init__(self) -> None:
        self._codes: list[int] = []
        self._lut: np.ndarray | None = None  # 2**24 entries: colour code -> index

    def __len__(self) -> int:
        return len(self._codes)

    @property
    def palette(self) -> np.ndarray:
        """The ``(K, 3)`` uint8 palette so far."""
        c = np.asarray(self._codes, dtype=np.uint32)
        return np.stack([c & 255, (c >> 8) & 255, (c >> 16) & 255], axis=1).astype(np.uint8)

    def encode(self, frames: np.ndarray) -> np.ndarray | None:
        """Indices ``(rows, H, W)`` of ``frames`` ``(rows, H, W, 3)``; ``None`` past 256 colours.

        On ``None`` the palette is left as it was before the call.
        """
        frames = np.ascontiguousarray(frames, dtype=np.uint8)
        if self._lut is None:
            self._lut = np.full(1 << 24, _UNKNOWN, dtype=np.uint8)
        codes = _pixel_codes(frames)
        idx = np.take(self._lut, codes)
        unknown = idx == _UNKNOWN
        if len(self._codes) == MAX_COLOURS:
            unknown &= codes != self._codes[_UNKNOWN]
        if unknown.any():
            seen = codes[unknown]
            new = self._new_colours(seen)
            k = len(self._codes)
            if k + len(new) > MAX_COLOURS:
                return None
            self._lut[new] = np.arange(k, k + len(new), dtype=np.uint8)
            self._codes.extend(int(c) for c in new)
            idx[unknown] = self._lut[seen]
        return idx.reshape(frames.shape[:-1])

    def _new_colours(self, seen: np.ndarray) -> np.ndarray:
        """Colours of ``seen`` (none in the palette) in order of first appearance.

        A few passes over ``seen`` find the first few colours (all of them for the mazes)
        faster than sorting it; many colours fall back to :func:`np.unique`.
        """
        found: list[int] = []
        while len(seen) and len(found) < 16:
            found.append(int(seen[0]))
            seen = seen[seen != seen[0]]
        rest = _first_appearances(seen) if len(seen) else np.empty(0, np.uint32)
        return np.concatenate([np.asarray(found, dtype=np.uint32), rest.astype(np.uint32)])


def _first_appearances(codes: np.ndarray) -> np.ndarray:
    """The distinct values of ``codes`` in order of first appearance."""
    values, first = np.unique(codes, return_index=True)
    return values[np.argsort(first, kind="stable")]


@functools.lru_cache(maxsize=16)
def _pair_table(padded: bytes, packed: bool) -> np.ndarray:
    """:class:`PaletteDecoder`'s table for a ``(256, 3)`` padded palette (read-only).

    Entry ``w`` is what the little-endian ``uint16`` ``w`` of two stored bytes decodes to:
    packed, 4 pixels (12 bytes of a ``V16`` entry); else 2 pixels (6 bytes of a ``<u8``).
    """
    palette = np.frombuffer(padded, dtype=np.uint8).reshape(MAX_COLOURS, 3)
    byte = np.arange(256)
    # The RGB bytes of one stored byte: two 4-bit indices (low nibble first), or one index.
    one = np.concatenate([palette[byte & 15], palette[byte >> 4]], 1) if packed else palette
    width = one.shape[1]
    table = np.zeros((256, 256, 16 if packed else 8), dtype=np.uint8)  # [high, low byte]
    table[:, :, :width] = one[None, :, :]  # the low byte comes first
    table[:, :, width : 2 * width] = one[:, None, :]
    table = table.reshape(1 << 16, -1).view("V16" if packed else "<u8").ravel()
    table.flags.writeable = False
    return table


def _fast_path_works() -> bool:
    """Check once that overlapping strided stores land in order (they do in numpy's loops)."""
    rng = np.random.default_rng(0)
    pal = rng.integers(256, size=(7, 3), dtype=np.uint8)
    idx = rng.integers(7, size=(3, 5, 6), dtype=np.uint8)
    ok = True
    for packed in (False, True):
        out = np.empty((*idx.shape, 3), dtype=np.uint8)
        dec = PaletteDecoder(pal, packed=packed, _fast=True)
        dec.decode_into(pack4(idx) if packed else idx, out)
        ok &= bool(np.array_equal(out, pal[idx]))
    return ok


class PaletteDecoder:
    """Decodes palette indices into RGB frames (``palette[indices]``, only faster).

    Args:
        palette: The ``(K, 3)`` uint8 palette.
        packed: Indices come two per byte (:func:`pack4`, encoding ``palette4``).

    Indices at or past ``len(palette)`` (a corrupt file) decode to black;
    :func:`abco_data.verify` reports them.
    """

    _fast_ok: bool | None = None
    #: Pixels decoded per numpy call (bounds the temporary gather buffer to about 1 MB).
    BLOCK_PIXELS = 1 << 18

    def __init__(self, palette: np.ndarray, *, packed: bool = False,
                 _fast: bool | None = None) -> None:
        palette = np.asarray(palette, dtype=np.uint8).reshape(-1, 3)
        self.palette, self.packed = palette, packed
        self._padded = np.zeros((MAX_COLOURS, 3), dtype=np.uint8)
        self._padded[: min(len(palette), MAX_COLOURS)] = palette[:MAX_COLOURS]
        if _fast is None:
            if PaletteDecoder._fast_ok is None:
                PaletteDecoder._fast_ok = _fast_path_works()
            _fast = PaletteDecoder._fast_ok
        self._fast = _fast

    @property
    def _table(self) -> np.ndarray | None:
        """The fast path's look-up table (built on first use, shared per palette), or None."""
        return _pair_table(self._padded.tobytes(), self.packed) if self._fast else None

    def out_shape(self, shape: tuple[int, ...]) -> tuple[int, ...]:
        """Shape of the frames decoded from stored data of ``shape``."""
        return (*shape[:-1], 2 * shape[-1], 3) if self.packed else (*shape, 3)

    def decode(self, data: np.ndarray) -> np.ndarray:
        """A new array of the frames of ``data`` (indices, or packed indices)."""
        out = np.empty(self.out_shape(data.shape), dtype=np.uint8)
        self.decode_into(data, out)
        return out

    def decode_into(self, data: np.ndarray, out: np.ndarray) -> None:
        """Write the frames of ``data`` into ``out`` (shape :meth:`out_shape`)."""
        if out.shape != self.out_shape(data.shape):
            raise ValueError(f"out has shape {out.shape}, expected"
                             f" {self.out_shape(data.shape)}")
        table = self._table
        if table is None or not out.flags.c_contiguous:
            out[...] = self._padded[unpack4(data) if self.packed else data]
            return
        flat = np.ascontiguousarray(data, dtype=np.uint8).reshape(-1)
        dest = out.reshape(-1)
        per_byte = 2 if self.packed else 1
        step = self.BLOCK_PIXELS // per_byte  # stored bytes per numpy call (even)
        for start in range(0, flat.size, step):
            piece = flat[start : start + step]
            at = 3 * per_byte * start
            target = dest[at : at + 3 * per_byte * len(piece)]
            if self.packed:
                self._groups_into(table, piece, target, 12, "V16")
            else:
                self._groups_into(table, piece, target, 6, "<u8")

    def _groups_into(self, table: np.ndarray, piece: np.ndarray, dest: np.ndarray, size: int,
                     dtype: str) -> None:
        """Look up each uint16 of ``piece``: ``size`` bytes of a ``table`` item stored each."""
        pairs = piece.size // 2
        n = pairs - 1  # groups by the fast path; its last store would end past ``dest``
        if n > 0:
            stores = np.ndarray((n,), dtype=dtype, buffer=dest, strides=(size,))
            # np.take, not fancy indexing: about twice as fast into a cache-sized block.
            stores[...] = np.take(table, piece[: 2 * n].view("<u2"))
        done = max(n, 0) * size
        if pairs:  # the last pair: its table entry's first ``size`` bytes
            entries = table.view(np.uint8).reshape(len(table), -1)
            dest[done : done + size] = entries[int(piece[2 * n]) | int(piece[2 * n + 1]) << 8,
                                               :size]
            done += size
        if piece.size % 2:  # an odd byte at the end
            rest = piece[-1:]
            dest[done:] = self._padded[unpack4(rest) if self.packed else rest].reshape(-1)
