"""The on-disk format: one HDF5 file per dataset, flat columns plus episode offsets.

This package is the only place that knows the layout described in ``docs/format.md``:

- :mod:`abco_data.format.schema`: the names of the columns and attributes, which action
  column each kind has, the row count of each column, the storage settings, the JSON
  encoding of spaces and the header checks a reader runs before trusting a file;
- :mod:`abco_data.format.writer`: :class:`DatasetWriter`, the atomic writer;
- :mod:`abco_data.format.handle`: :class:`LazyH5File`, pinned to one file (:class:`FileIdentity`);
- :mod:`abco_data.format.reader`: :func:`open_h5` and
  :class:`ObservationReader`, which decodes palette-encoded observations
  (:mod:`abco_data.format.palette`), with HDF5's errors turned into ones naming the file;
- :mod:`abco_data.format.heaps`: the check that keeps HDF5 from looping forever on a damaged
  global heap (run before every open).

Every name is importable from ``abco_data.format`` itself.

Example:
    >>> from gymnasium import spaces
    >>> space_from_json(space_to_json(spaces.Discrete(4)))
    Discrete(4)
    >>> required_columns("expert")[3:5]
    ('truncations', 'idm_eval_actions')
"""

from abco_data.format.handle import FileIdentity, LazyH5File
from abco_data.format.heaps import check_global_heaps
from abco_data.format.reader import (
    HDF5_ERRORS,
    ObservationReader,
    h5_column,
    hdf5_errors,
    open_h5,
    open_h5_file,
    read_column,
    read_rows,
)
from abco_data.format.schema import (
    ACTION_COLUMNS,
    ACTIONS,
    EPISODE_COLUMNS,
    EPISODES,
    FLAT_COLUMNS,
    FORMAT_NAME,
    FORMAT_VERSION,
    GZIP_LEVEL,
    IDM_EVAL_ACTIONS,
    IMAGE_CHUNK_ROWS,
    IMAGE_GZIP_LEVEL,
    KINDS,
    MAZE_EPISODE_COLUMNS,
    OBSERVATION_ENCODINGS,
    OBSERVATIONS,
    PALETTE,
    POSITIONS,
    REFERENCE_COLUMNS,
    REQUIRED_ROOT_ATTRS,
    REWARDS,
    TERMINATIONS,
    TRUNCATIONS,
    VECTOR_CHUNK_BYTES,
    action_column,
    attr_value,
    check_header,
    chunk_rows,
    episode_column,
    expected_rows,
    required_columns,
    space_from_json,
    space_to_json,
    to_json,
)
from abco_data.format.writer import DatasetWriter

__all__ = [
    "ACTIONS", "ACTION_COLUMNS", "EPISODES", "EPISODE_COLUMNS", "FLAT_COLUMNS", "FORMAT_NAME",
    "FORMAT_VERSION", "GZIP_LEVEL", "IDM_EVAL_ACTIONS", "IMAGE_CHUNK_ROWS", "IMAGE_GZIP_LEVEL",
    "KINDS", "MAZE_EPISODE_COLUMNS", "OBSERVATIONS", "OBSERVATION_ENCODINGS", "PALETTE",
    "POSITIONS", "REFERENCE_COLUMNS", "REQUIRED_ROOT_ATTRS", "REWARDS", "TERMINATIONS",
    "TRUNCATIONS", "VECTOR_CHUNK_BYTES", "HDF5_ERRORS", "DatasetWriter", "FileIdentity",
    "LazyH5File",
    "ObservationReader", "action_column", "attr_value", "check_global_heaps", "check_header",
    "chunk_rows", "episode_column", "expected_rows", "h5_column", "hdf5_errors", "open_h5",
    "open_h5_file",
    "read_column", "read_rows", "required_columns",
    "space_from_json", "space_to_json", "to_json",
]
