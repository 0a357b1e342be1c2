"""The maze envs' arguments, checked once for both the single and the vector env.

Example:
    >>> resolve_image_size(64)
    (64, 64)
    >>> check_env_options(5, "image", "train")
    >>> check_env_options(5, "pixels", "train")
    Traceback (most recent call last):
    ...
    ValueError: unknown obs_type 'pixels'; expected one of ('image', 'state')
"""

from __future__ import annotations

import numpy as np

from abco_envs.maze.observation import OBS_TYPES
from abco_envs.maze.pool import SPLITS

__all__ = ["LAYOUT_SOURCES", "check_env_options", "resolve_image_size"]

#: The values of the ``split`` argument: the pool's splits, or fresh layouts.
LAYOUT_SOURCES = (*SPLITS, "procedural")


def check_env_options(size: int, obs_type: str, split: str) -> None:
    """Check the arguments every maze env takes.

    Raises:
        ValueError: An unknown ``obs_type`` or ``split``, or fewer than 2x2 cells.
    """
    if obs_type not in OBS_TYPES:
        raise ValueError(f"unknown obs_type {obs_type!r}; expected one of {OBS_TYPES}")
    if split not in LAYOUT_SOURCES:
        raise ValueError(f"unknown split {split!r}; expected one of {LAYOUT_SOURCES}")
    if size < 2:
        raise ValueError(f"a maze needs at least 2x2 cells, got size={size}")


def resolve_image_size(image_size: int | tuple[int, int]) -> tuple[int, int]:
    """``64`` -> ``(64, 64)``; ``(h, w)`` stays as it is."""
    if isinstance(image_size, (int, np.integer)):
        return int(image_size), int(image_size)
    height, width = (int(v) for v in image_size)
    return height, width
