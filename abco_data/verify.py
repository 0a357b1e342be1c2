"""Checking a dataset file completely: its bytes, every value, every invariant.

:func:`check_dataset` is what a program calls before trusting a file given by path as it
would trust one from the cache: it opens the file (format version, kind, environment), checks
its size and sha256 (see :mod:`abco_data.checks.checksum`: the manifest's, or the bytes abco
generates for what the file claims to be), then reads every value: finite numbers, actions in
the action space, episodes that end where they should, observations inside the observation
space, and for mazes each move consistent with the walls and every frame re-rendered from its
layout and agent position. :func:`verify` does the same for ``abco data verify`` and returns a
:class:`VerifyReport`; it takes a path or a dataset id (the cache's copy), and can run in a
child process with a time limit.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np

from abco_data.checks.checksum import ExpectedDigest, check_checksum, expected_digest
from abco_data.dataset import Dataset, open_dataset
from abco_data.errors import ChecksumError, CorruptDatasetError, WrongKindError
from abco_data.format.arrays import DatasetArrays
from abco_data.format.files import file_digest, sha256_of
from abco_data.format.validation import MazeColumns, maze_columns
from abco_data.generation.generate import layout_split
from abco_data.hub.manifest import Manifest, as_manifest, cached_path, known_ids
from abco_data.user.datasets import user_dataset_file
from abco_data.user.forked_call import run_in_child
from abco_data.user.ids import is_user_id
from abco_envs.maze.procedural import PROCEDURAL_SPLIT_SIZE

__all__ = ["VerifyReport", "check_dataset", "verify", "sha256_of"]

T = TypeVar("T")


@dataclass(frozen=True)
class VerifyReport:
    """What :func:`verify` checked.

    Attributes:
        path: The file.
        dataset_id: Its dataset id.
        size: File size in bytes.
        sha256: Hex sha256 of the file.
        num_episodes: Episodes.
        num_transitions: Transitions.
        frames_rendered: Maze frames re-rendered and compared (0 outside mazes).
        checksum: What the size and sha256 were checked against ("" if nothing was known).
    """

    path: Path
    dataset_id: str
    size: int
    sha256: str
    num_episodes: int
    num_transitions: int
    frames_rendered: int
    checksum: str = ""


def _split_ids(m: MazeColumns, ds: Dataset, path: Path) -> tuple[tuple[str, ...], str]:
    """The structural ids that ``layout_index`` indexes, and what they are, for messages."""
    from abco_envs.maze.procedural import procedural_ids

    try:
        split = layout_split(json.loads(ds.attrs["creation_params"]))
    except (TypeError, ValueError, AttributeError) as err:  # the file's JSON and its claims
        raise CorruptDatasetError(f"{path}: creation_params name no layout split a dataset"
                                  f" can be made from: {err}") from err
    if split == "procedural":
        count = int(m.layout_indices.max()) + 1 if len(m.layout_indices) else 0
        if count > PROCEDURAL_SPLIT_SIZE:
            raise CorruptDatasetError(f"{path}: layout index {count - 1} is beyond the"
                                      f" {PROCEDURAL_SPLIT_SIZE} layouts of the procedural split")
        return procedural_ids(m.layouts.shape[1], count), "the procedural split"
    ref = ds.reference
    # Only the train split's layouts: a test layout in a dataset would leak the held-out set.
    train = tuple(i for i, split in zip(ref.layout_ids or (), ref.layout_splits or ())
                  if split == "train")
    return train, "the train split"


def _check_maze(a: DatasetArrays, m: MazeColumns, ds: Dataset, path: Path) -> int:
    """Moves follow the walls, layouts are their split's, every frame re-renders.

    Returns the number of frames re-rendered.
    """
    from abco_envs.maze.layout import DELTAS, OPEN_BITS, layout_hash
    from abco_envs.maze.render import MazeRenderer

    ids, where = _split_ids(m, ds, path)
    for e, (layout, k) in enumerate(zip(m.layouts, m.layout_indices)):
        if k >= len(ids) or layout_hash(layout) != ids[k]:
            raise CorruptDatasetError(f"{path}: episode {e}'s layout is not layout {k} of"
                                      f" {where}")
    episode_of_row = np.repeat(np.arange(len(a.episode_lengths)), a.episode_lengths + 1)
    obs_t, _ = ds.transition_index()
    actions = a.actions if a.actions is not None else a.idm_eval_actions
    r, c = m.positions[obs_t].T
    open_side = (m.layouts[episode_of_row[obs_t], r, c] & OPEN_BITS[actions]) > 0
    expected = m.positions[obs_t] + DELTAS[actions] * open_side[:, None]
    wrong = np.flatnonzero(np.any(expected != m.positions[obs_t + 1], axis=1))
    if len(wrong):
        raise CorruptDatasetError(f"{path}: transition {int(wrong[0])} moves the agent in a way"
                                  " its action and the maze walls do not allow")
    n = m.layouts.shape[1]
    renderer = MazeRenderer(n, *a.observations.shape[1:3])
    for e in range(len(a.episode_lengths)):
        start, stop = a.episode_starts[e], a.episode_starts[e] + a.episode_lengths[e] + 1
        background = renderer.background(m.layouts[e])
        for row in range(start, stop):
            r, c = m.positions[row]
            frame = renderer.draw_agent(background.copy(), int(r), int(c))
            if not np.array_equal(frame, a.observations[row]):
                raise CorruptDatasetError(
                    f"{path}: observation {row} (episode {e}) does not match its layout and"
                    f" agent position ({r}, {c})")
    return int(a.episode_lengths.sum() + len(a.episode_lengths))


def _check_values(ds: Dataset) -> int:
    """Every value of ``ds`` (see the module docstring); returns the frames re-rendered."""
    a = ds.load_arrays()  # finite values, spaces, episode ends: abco_data.format.validation
    maze = maze_columns(a, ds.path)
    return _check_maze(a, maze, ds, ds.path) if maze is not None else 0


def _resolve(source: str | os.PathLike[str] | Dataset,
             manifest: Manifest) -> tuple[Path, str | None]:
    """The file to check and the id it must hold (given an id: the cache's copy, or a
    registered user dataset's file)."""
    if isinstance(source, Dataset):
        return source.path, None
    path = Path(source)
    if isinstance(source, str) and not path.exists() and source in known_ids(manifest):
        return cached_path(source, manifest=manifest), source
    if isinstance(source, str) and not path.exists() and is_user_id(source):
        return user_dataset_file(source), source  # its size and sha256 checked on the way
    return path, None


def check_dataset(source: str | os.PathLike[str] | Dataset, *, kind: str | None = None,
                  env_id: str | None = None, dataset_id: str | None = None,
                  manifest: Manifest | str | os.PathLike[str] | None = None) -> Dataset:
    """Check a dataset file completely, as one from the cache is checked; return it opened.

    Args:
        source: The file's path, a dataset id (its copy in the abco cache, or the file of a
            registered user dataset), or an opened :class:`~abco_data.dataset.Dataset`
            (returned as it is once checked).
        kind: The kind it must be (``"expert"`` or ``"pre_demonstrations"``).
        env_id: The environment it must be for, e.g. ``"CartPole-v1"``.
        dataset_id: The dataset id it must hold.
        manifest: A manifest or the path of one; default the shipped one.

    Returns:
        The opened dataset.

    Raises:
        DatasetFileNotFoundError: No such file.
        FormatVersionError: A ``format_version`` this abco does not read.
        WrongKindError: Another kind, environment or id than asked for.
        ChecksumError: Bytes other than those the manifest (or the generator, for a
            variant) gives for what the file claims to be.
        CorruptDatasetError: Anything else wrong: unreadable, inconsistent, non-finite values.

    Example:
        >>> import tempfile, os, abco_data
        >>> path = abco_data.generate("abco/mountaincar-pre-v0", os.path.join(
        ...     tempfile.mkdtemp(), "m.hdf5"), progress=False, transitions=30,
        ...     reference_episodes=1, reference_expert_episodes=1)
        >>> check_dataset(path, kind="pre_demonstrations", env_id="MountainCar-v0").id
        'abco/mountaincar-pre-v0'
        >>> check_dataset(path, kind="expert")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        abco_data.errors.WrongKindError: ...m.hdf5: holds pre_demonstrations data ...
    """
    man = as_manifest(manifest)
    path, from_id = _resolve(source, man)
    ds = source if isinstance(source, Dataset) else open_dataset(
        path, dataset_id=dataset_id or from_id, kind=kind)
    if isinstance(source, Dataset):
        open_dataset(path, dataset_id=dataset_id, kind=kind).close()
    if env_id is not None and ds.env_id != env_id.split(":")[-1]:
        raise WrongKindError(f"{path}: holds data of {ds.env_id}, not {env_id}")
    try:
        expected = expected_digest(ds, manifest=man)
        if expected is not None:
            check_checksum(path, expected)
        _check_values(ds)
    except BaseException:
        if not isinstance(source, Dataset):
            ds.close()
        raise
    return ds


def _explicit(sha256: str | None, size: int | None) -> ExpectedDigest | None:
    if sha256 is None and size is None:
        return None
    return ExpectedDigest(size if size is not None else -1, (sha256 or "").lower(),
                          "the expected values given")


def _verify(source: str | os.PathLike[str], sha256: str | None, size: int | None,
            manifest: Manifest) -> VerifyReport:
    path, from_id = _resolve(source, manifest)
    ds = open_dataset(path, dataset_id=from_id)
    try:
        expected = _explicit(sha256, size) or expected_digest(ds, manifest=manifest)
        actual_size, digest = file_digest(path)
        if expected is not None and (expected.size not in (-1, actual_size)
                                     or expected.sha256 not in ("", digest)):
            raise ChecksumError(
                f"{path}: size {actual_size} bytes and sha256 {digest} do not match"
                f" {expected.source}: {'?' if expected.size < 0 else expected.size} bytes"
                f" with sha256 {expected.sha256 or '?'}")
        rendered = _check_values(ds)
    finally:
        ds.close()
    return VerifyReport(path, ds.id, actual_size, digest, ds.num_episodes, ds.num_transitions,
                        rendered, expected.source if expected is not None else "")


def verify(source: str | os.PathLike[str], *, sha256: str | None = None,
           size: int | None = None,
           manifest: Manifest | str | os.PathLike[str] | None = None,
           timeout: float | None = None) -> VerifyReport:
    """Check every byte and value of a dataset file (see :func:`check_dataset`).

    Args:
        source: The file, or a dataset id (the abco cache's copy, or the file of a
            registered user dataset).
        sha256: Expected hex sha256; default what :mod:`abco_data.checks.checksum` knows for the
            dataset the file claims to be (the manifest's entry, or the generator's bytes).
        size: Expected size in bytes (with the same default).
        manifest: A manifest or the path of one; default the shipped one.
        timeout: Run the check in a child process and give up after this many seconds (the
            HDF5 library has had loops on damaged files); None runs it here.

    Raises:
        ChecksumError: Size or sha256 differ from the expected ones.
        CorruptDatasetError: Unreadable data, a broken invariant, or (with ``timeout``) a
            check that did not finish in time.
        FormatVersionError: Another ``format_version``.
    """
    man = as_manifest(manifest)
    if timeout is None:
        return _verify(source, sha256, size, man)
    return run_with_time_limit(lambda: _verify(source, sha256, size, man), timeout,
                               f"verifying {source}")


def run_with_time_limit(fn: Callable[[], T], timeout: float, what: str) -> T:
    """``fn()`` in a forked child process: its result, or its exception raised here.

    Calls ``fn()`` here where ``os.fork`` does not exist.

    Raises:
        CorruptDatasetError: The child ran past ``timeout`` seconds (it is killed) or died
            (a crash in a native library).
    """
    if not hasattr(os, "fork"):  # pragma: no cover - Windows
        return fn()
    outcome = run_in_child(fn, timeout)
    if outcome.timed_out:
        raise CorruptDatasetError(f"{what} did not finish in {timeout:g} s (the file is most"
                                  " likely damaged)")
    if not outcome.finished:
        raise CorruptDatasetError(f"{what} crashed the checking process ({outcome.signal}):"
                                  " the file is most likely damaged")
    if outcome.error is not None:
        raise outcome.error
    return outcome.value
