"""The header of an open dataset file, read and checked: what :func:`open_dataset` trusts.

:func:`read_header` checks the format (:func:`~abco_data.format.check_header`), that the id
agrees with the env and kind (and is one abco knows, or a user id:
:mod:`abco_data.user.ids`), the counts and the episode offsets
against the columns, the reference returns, and the spaces against the stored observations;
it reads no bulk data.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from gymnasium import spaces

from abco_data.errors import CorruptDatasetError, WrongKindError
from abco_data.format import (
    POSITIONS,
    REFERENCE_COLUMNS,
    ObservationReader,
    check_header,
    episode_column,
    expected_rows,
    h5_column,
    hdf5_errors,
    read_column,
    space_from_json,
)
from abco_data.generation.generate import GENERATOR
from abco_data.generation.reference import ReferenceReturns
from abco_data.hub.manifest import read_manifest
from abco_data.registry import ACTION_COUNTS, DATASET_IDS, spec
from abco_data.user.ids import is_user_id

__all__ = ["Header", "read_header", "read_whole_column"]


@dataclass(frozen=True)
class Header:
    """The checked header of a file.

    Attributes:
        attrs: Every root attribute (plain Python values).
        observation_space: The observation space.
        action_space: The ``Discrete`` action space.
        reference: The reference returns.
    """

    attrs: dict[str, Any]
    observation_space: spaces.Space[Any]
    action_space: spaces.Discrete
    reference: ReferenceReturns


def read_whole_column(ds: h5py.Dataset, path: Path, rows: int | None = None) -> np.ndarray:
    """Read a whole column, or its first ``rows`` rows, into one fresh array."""
    with hdf5_errors(path, f"column {ds.name}"):
        if rows is None or rows >= len(ds):
            out = np.empty(ds.shape, dtype=ds.dtype)
            if out.size:
                read_column(ds, out)
        else:
            out = np.empty((rows, *ds.shape[1:]), dtype=ds.dtype)
            if out.size:
                ds.read_direct(out, np.s_[0:rows], np.s_[0:rows])
    return out


def _count(attrs: Mapping[str, Any], name: str, path: Path) -> int:
    value = attrs[name]
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise CorruptDatasetError(f"{path}: root attribute {name} must be a count, got"
                                  f" {value!r}")
    return value


def _finite_float(attrs: Mapping[str, Any], name: str, path: Path) -> float:
    value = attrs[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not np.isfinite(value):
        raise CorruptDatasetError(f"{path}: root attribute {name} must be a finite number,"
                                  f" got {value!r}")
    return float(value)


def _space(attrs: Mapping[str, Any], name: str, path: Path) -> spaces.Space[Any]:
    text = attrs[name]
    try:
        if not isinstance(text, str):
            raise TypeError(f"not a string but {type(text).__name__}")
        return space_from_json(text)
    except (ValueError, KeyError, TypeError) as err:  # parsing the file's JSON, nothing else
        raise CorruptDatasetError(f"{path}: root attribute {name} is not a valid space:"
                                  f" {err}") from err


def _reference(f: h5py.File, attrs: Mapping[str, Any], path: Path) -> ReferenceReturns:
    expert_mean = _finite_float(attrs, "reference_expert_mean", path)
    random_mean = _finite_float(attrs, "reference_random_mean", path)
    if REFERENCE_COLUMNS[0] not in f:
        return ReferenceReturns(expert_mean, random_mean)
    ids, splits, expert, random = (h5_column(f, c)[()] for c in REFERENCE_COLUMNS)
    try:
        ids, splits = (tuple(s.decode() for s in column) for column in (ids, splits))
    except (AttributeError, UnicodeDecodeError) as err:  # not byte strings
        raise CorruptDatasetError(f"{path}: reference layout ids are not strings") from err
    if not (len(ids) == len(splits) == len(expert) == len(random)) \
            or not (np.isfinite(expert).all() and np.isfinite(random).all()):
        raise CorruptDatasetError(f"{path}: reference returns are inconsistent")
    return ReferenceReturns(expert_mean, random_mean, ids, splits, expert, random)


def _check_identity(attrs: Mapping[str, Any], path: Path, dataset_id: str | None,
                    kind: str | None) -> None:
    """The file holds the id and kind asked for, and its id agrees with its env and kind."""
    if kind is not None and attrs["kind"] != kind:
        raise WrongKindError(f"{path}: holds {attrs['kind']} data"
                             f" ({attrs['dataset_id']}), not {kind}")
    if dataset_id is not None and attrs["dataset_id"] != dataset_id:
        raise WrongKindError(f"{path}: holds dataset {attrs['dataset_id']!r},"
                             f" not {dataset_id!r}")
    claimed = attrs["dataset_id"]
    if claimed in DATASET_IDS:
        s = spec(claimed)
        if (attrs["env_id"], attrs["kind"]) != (s.env_id, s.kind):
            raise CorruptDatasetError(
                f"{path}: claims dataset {claimed} ({s.env_id}, {s.kind}) but holds"
                f" {attrs['env_id']!r} {attrs['kind']!r} data")
    elif claimed not in read_manifest().files and not (
            is_user_id(claimed) and attrs["generator"] != GENERATOR):  # it writes built-ins only
        raise CorruptDatasetError(f"{path}: holds an unknown dataset id {claimed!r}")


def _check_chunks(ds: h5py.Dataset, path: Path, file_size: int) -> None:
    """Every chunk of a chunked column is stored, where the writer put it: inside the file,
    and at the logical position of each block of rows. HDF5 reads a chunk whose index entry
    is lost, zeroed or moved as zeros, without an error."""
    if ds.chunks is None or not len(ds):
        return
    rows = ds.chunks[0]
    expected = [(i * rows,) + (0,) * (ds.ndim - 1) for i in range(-(-len(ds) // rows))]
    stored: list[tuple[tuple[int, ...], int, int]] = []
    ds.id.chunk_iter(lambda c: stored.append((c.chunk_offset, c.byte_offset, c.size)))
    if sorted(offset for offset, _, _ in stored) != expected or any(
            at <= 0 or size <= 0 or at + size > file_size for _, at, size in stored):
        raise CorruptDatasetError(f"{path}: column {ds.name} has a damaged chunk index (its"
                                  " chunks are not all where the writer put them)")


def _check_counts(f: h5py.File, attrs: Mapping[str, Any], path: Path) -> None:
    file_size = path.stat().st_size
    n_ep, n_tr = _count(attrs, "num_episodes", path), _count(attrs, "num_transitions", path)
    if _count(attrs, "num_observations", path) != n_ep + n_tr:
        raise CorruptDatasetError(f"{path}: num_observations is not num_transitions +"
                                  " num_episodes")
    for col, n in expected_rows(attrs["kind"], n_ep, n_tr, maze=POSITIONS in f).items():
        if col not in f:
            raise CorruptDatasetError(f"{path}: missing column {col}")
        ds = h5_column(f, col)
        if ds.shape[:1] != (n,):
            raise CorruptDatasetError(f"{path}: column {col} has shape {ds.shape},"
                                      f" expected {n} rows from the root attributes")
        _check_chunks(ds, path, file_size)
    lengths, starts, obs_starts = (read_whole_column(h5_column(f, episode_column(key)), path)
                                   for key in ("length", "transition_offset", "obs_offset"))
    cum = np.concatenate([[0], np.cumsum(lengths)[:-1]]) if n_ep else lengths
    if (lengths.sum() != n_tr or np.any(lengths < 1) or np.any(starts != cum)
            or np.any(obs_starts != starts + np.arange(n_ep))):
        raise CorruptDatasetError(f"{path}: episode offsets and lengths are inconsistent")


def read_header(f: h5py.File, path: Path, *, dataset_id: str | None = None,
                kind: str | None = None) -> Header:
    """Read and check the header of open file ``f`` (see the module docstring).

    Raises:
        CorruptDatasetError: Not an abco dataset, or an inconsistent one.
        FormatVersionError: Another ``format_version``.
        WrongKindError: Another id or kind than asked for.
    """
    attrs = check_header(f, path)
    _check_identity(attrs, path, dataset_id, kind)
    _check_counts(f, attrs, path)
    reference = _reference(f, attrs, path)
    obs_space = _space(attrs, "observation_space", path)
    act_space = _space(attrs, "action_space", path)
    reader = ObservationReader(f)
    if reader.shape[1:] != obs_space.shape or reader.dtype != obs_space.dtype:
        raise CorruptDatasetError(
            f"{path}: observations are {reader.dtype} {reader.shape[1:]}, the observation"
            f" space {obs_space.dtype} {obs_space.shape}")
    expected_actions = ACTION_COUNTS.get(attrs["env_id"])
    if not isinstance(act_space, spaces.Discrete) or (
            expected_actions is not None and act_space.n != expected_actions):
        raise CorruptDatasetError(f"{path}: action space {act_space} is not the one of"
                                  f" {attrs['env_id']}")
    return Header(attrs, obs_space, act_space, reference)
