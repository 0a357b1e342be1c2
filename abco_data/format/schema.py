"""The schema of an abco dataset file: every name, kind and rule of ``docs/format.md``.

Column and attribute names, which action column each kind has, the columns of mazes, the
row count each column must have, the storage settings of each column, the JSON encoding of
spaces, and the header check a reader runs before trusting a file. Nothing else in abco_data
spells a column name.

Example:
    >>> action_column("expert"), action_column("pre_demonstrations")
    ('idm_eval_actions', 'actions')
    >>> episode_column("length")
    'episodes/length'
    >>> space_from_json(space_to_json(spaces.Discrete(4)))
    Discrete(4)
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from abco_data.errors import CorruptDatasetError, FormatVersionError

__all__ = [
    "FORMAT_NAME", "FORMAT_VERSION", "KINDS", "REQUIRED_ROOT_ATTRS", "OBSERVATION_ENCODINGS",
    "OBSERVATIONS", "PALETTE", "ACTIONS", "IDM_EVAL_ACTIONS", "REWARDS", "TERMINATIONS",
    "TRUNCATIONS", "POSITIONS", "EPISODES", "FLAT_COLUMNS", "EPISODE_COLUMNS",
    "MAZE_EPISODE_COLUMNS", "REFERENCE_COLUMNS", "ACTION_COLUMNS", "action_column",
    "episode_column", "required_columns", "expected_rows", "GZIP_LEVEL", "IMAGE_GZIP_LEVEL",
    "IMAGE_CHUNK_ROWS", "VECTOR_CHUNK_BYTES", "chunk_rows", "to_json", "space_to_json",
    "space_from_json", "attr_value", "check_header",
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

# -- columns -------------------------------------------------------------------------------

#: Observations, ``T + 1`` rows per episode (palette indices when encoded).
OBSERVATIONS = "observations"
#: The ``(K, 3)`` RGB palette of palette-encoded observations.
PALETTE = "observation_palette"
#: Training actions: pre-demonstrations only.
ACTIONS = "actions"
#: The expert's actions: expert data only, for measuring IDM accuracy, never for training.
IDM_EVAL_ACTIONS = "idm_eval_actions"
REWARDS = "rewards"
TERMINATIONS = "terminations"
TRUNCATIONS = "truncations"
#: Mazes: the agent's ``(row, col)`` in each observation.
POSITIONS = "positions"
#: The group of per-episode columns.
EPISODES = "episodes"
#: Flat columns every file carries (plus the action column of its kind).
FLAT_COLUMNS = (OBSERVATIONS, REWARDS, TERMINATIONS, TRUNCATIONS)
#: Per-episode columns (under :data:`EPISODES`) every file carries.
EPISODE_COLUMNS = ("obs_offset", "transition_offset", "length", "seed", "return")
#: Per-episode columns of maze files only.
MAZE_EPISODE_COLUMNS = ("layout_index", "layout")
#: The per-layout reference returns of maze files.
REFERENCE_COLUMNS = ("reference/layout_ids", "reference/layout_splits",
                     "reference/expert_return", "reference/random_return")
#: The action column of each kind.
ACTION_COLUMNS: Mapping[str, str] = {"expert": IDM_EVAL_ACTIONS,
                                     "pre_demonstrations": ACTIONS}


def action_column(kind: str) -> str:
    """The action column of a dataset of ``kind`` (see :data:`ACTION_COLUMNS`).

    Raises:
        ValueError: Not one of :data:`KINDS`.
    """
    try:
        return ACTION_COLUMNS[kind]
    except KeyError:
        raise ValueError(f"unknown dataset kind {kind!r}; expected one of {KINDS}") from None


def episode_column(name: str) -> str:
    """The path of per-episode column ``name`` (``"episodes/<name>"``)."""
    return f"{EPISODES}/{name}"


def required_columns(kind: str) -> tuple[str, ...]:
    """Every column a file of ``kind`` carries, mazes or not."""
    return (*FLAT_COLUMNS, action_column(kind), *(episode_column(c) for c in EPISODE_COLUMNS))


def expected_rows(kind: str, num_episodes: int, num_transitions: int,
                  maze: bool) -> dict[str, int]:
    """The number of rows of each column of a file with these counts."""
    n_ep, n_tr = num_episodes, num_transitions
    rows = {OBSERVATIONS: n_tr + n_ep, action_column(kind): n_tr, REWARDS: n_tr,
            TERMINATIONS: n_tr, TRUNCATIONS: n_tr}
    rows.update({episode_column(c): n_ep for c in EPISODE_COLUMNS})
    if maze:
        rows[POSITIONS] = n_tr + n_ep
        rows.update({episode_column(c): n_ep for c in MAZE_EPISODE_COLUMNS})
    return rows


# -- storage ---------------------------------------------------------------------------------

#: Gzip level of vector columns (small; level 6 halves level 1's size).
GZIP_LEVEL = 6
#: Gzip level of image-like columns (rows of 2+ dimensions), measured in docs/format.md: on
#: packed palette indices level 3 is 2.4x smaller than level 1, as fast to write, and
#: inflates fastest; level 6 is a third smaller but writes twice as slowly.
IMAGE_GZIP_LEVEL = 3
#: Rows per chunk of an image-like column; other columns use ``VECTOR_CHUNK_BYTES`` chunks.
IMAGE_CHUNK_ROWS = 64
VECTOR_CHUNK_BYTES = 1 << 16


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


# -- JSON attributes -------------------------------------------------------------------------


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


# -- header check ----------------------------------------------------------------------------


def attr_value(value: Any) -> Any:
    """An HDF5 attribute as plain Python: bytes decoded, numpy scalars and arrays unwrapped.

    Example:
        >>> attr_value(b"abc"), attr_value(np.int64(3)), attr_value(np.array([b"a", b"b"]))
        ('abc', 3, ['a', 'b'])
    """
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.ndarray):
        return [attr_value(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return value.item()
    return value


def check_header(f: Any, path: Any) -> dict[str, Any]:
    """Check the format name, version, kind and columns of open file ``f``; return its
    root attributes.

    Raises:
        CorruptDatasetError: Not an abco dataset, or a required attribute or column is missing.
        FormatVersionError: A ``format_version`` other than :data:`FORMAT_VERSION`.
    """
    try:
        attrs = {k: attr_value(v) for k, v in f.attrs.items()}
    except (TypeError, UnicodeDecodeError) as err:  # h5py decoding a damaged attribute type
        raise CorruptDatasetError(f"{path}: root attributes cannot be read (corrupt file):"
                                  f" {err}") from err
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
    absent = [c for c in required_columns(attrs["kind"]) if c not in f]
    if absent:
        raise CorruptDatasetError(f"{path}: missing column(s) {', '.join(absent)}")
    return attrs
