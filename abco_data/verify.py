"""Deep verification of a dataset file: every value read, every invariant checked.

:func:`verify` goes further than :func:`~abco_data.dataset.open_dataset`: it decompresses
every chunk, checks that palette indices name palette entries, that only each episode's last
transition ends it, that stored returns are the sums of the rewards, that observations lie in
the observation space, re-renders every maze frame from its layout and agent position, and
compares size and sha256 with expected values when given.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abco_data.dataset import DatasetArrays, open_dataset
from abco_data.errors import ChecksumError, CorruptDatasetError
from abco_data.files import sha256_of
from abco_data.format import ObservationReader, open_h5
from abco_data.palette import unpack4

__all__ = ["VerifyReport", "verify", "sha256_of"]


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
    """

    path: Path
    dataset_id: str
    size: int
    sha256: str
    num_episodes: int
    num_transitions: int
    frames_rendered: int


def _check_episode_ends(a: DatasetArrays, path: Path) -> None:
    ends = a.episode_transition_starts + a.episode_lengths - 1
    last = np.zeros(len(a.rewards), dtype=bool)
    last[ends] = True
    if np.any((a.terminations | a.truncations) & ~last):
        raise CorruptDatasetError(f"{path}: an episode ends before its last transition")
    if not np.all(a.terminations[ends] | a.truncations[ends]):
        raise CorruptDatasetError(f"{path}: an episode's last transition neither terminates"
                                  " nor truncates it")
    sums = np.add.reduceat(a.rewards, a.episode_transition_starts) if len(ends) else ends
    if not np.allclose(sums, a.episode_returns, rtol=0, atol=1e-9):
        raise CorruptDatasetError(f"{path}: stored episode returns differ from reward sums")


def _check_palette(path: Path) -> None:
    """Every palette index of palette-encoded observations names a palette entry."""
    with open_h5(path) as f:
        _check_palette_indices(ObservationReader(f), path)


def _check_palette_indices(reader: ObservationReader, path: Path) -> None:
    if reader.palette is None:
        return
    k, step = len(reader.palette), 4096
    for start in range(0, len(reader), step):
        block = reader.ds[start : start + step]
        if reader.encoding == "palette4":
            block = unpack4(block)
        if block.size and int(block.max()) >= k:
            raise CorruptDatasetError(
                f"{path}: observations {start}..{start + len(block) - 1} hold palette"
                f" index {int(block.max())}, but observation_palette has {k} entries")


def _render_check(a: DatasetArrays, path: Path) -> int:
    """Re-render every maze frame from layout + position; return how many were compared."""
    from abco_envs.maze.render import MazeRenderer

    n = a.layouts.shape[1]
    h, w = a.observations.shape[1:3]
    renderer = MazeRenderer(n, h, w)
    for e in range(len(a.episode_lengths)):
        start, stop = a.episode_starts[e], a.episode_starts[e] + a.episode_lengths[e] + 1
        background = renderer.background(a.layouts[e])
        for row in range(start, stop):
            r, c = a.positions[row]
            frame = renderer.draw_agent(background.copy(), int(r), int(c))
            if not np.array_equal(frame, a.observations[row]):
                raise CorruptDatasetError(
                    f"{path}: observation {row} (episode {e}) does not match its layout and"
                    f" agent position ({r}, {c})")
    return int(a.episode_lengths.sum() + len(a.episode_lengths))


def verify(path: str | os.PathLike[str], *, sha256: str | None = None,
           size: int | None = None) -> VerifyReport:
    """Read and check every value of a dataset file.

    Args:
        path: The file.
        sha256: Expected hex sha256, if any.
        size: Expected size in bytes, if any.

    Raises:
        ChecksumError: Size or sha256 differ from the expected ones.
        CorruptDatasetError: Unreadable data or a broken invariant.
        FormatVersionError: Another ``format_version``.
    """
    path = Path(path)
    actual_size = path.stat().st_size if path.is_file() else -1
    if size is not None and actual_size != size:
        raise ChecksumError(f"{path}: size {actual_size} bytes, expected {size}")
    digest = sha256_of(path) if path.is_file() else ""
    if sha256 is not None and digest != sha256:
        raise ChecksumError(f"{path}: sha256 {digest} does not match the expected {sha256}")
    ds = open_dataset(path)
    try:
        a = ds.load_arrays()
        _check_episode_ends(a, path)
        space = ds.observation_space
        if a.observations.dtype != space.dtype or np.any(a.observations < space.low) \
                or np.any(a.observations > space.high):
            raise CorruptDatasetError(f"{path}: observations outside the observation space")
        actions = getattr(a, ds.action_column)
        if len(actions) and (actions.min() < 0 or actions.max() >= ds.action_space.n):
            raise CorruptDatasetError(f"{path}: actions outside the action space")
        _check_palette(path)
        rendered = _render_check(a, path) if a.positions is not None else 0
    finally:
        ds.close()
    return VerifyReport(path, ds.id, actual_size, digest, ds.num_episodes,
                        ds.num_transitions, rendered)
