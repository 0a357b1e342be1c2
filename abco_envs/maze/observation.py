"""What the mazes show: the observation spaces and the state vector's walls part.

Shared by :class:`~abco_envs.maze.env.MazeEnv` and
:class:`~abco_envs.maze.vector.MazeVectorEnv`, so both describe an observation the same way.

Example:
    >>> import numpy as np
    >>> from abco_envs.maze.rules import OPEN_E, OPEN_W
    >>> state_observation_space(2).shape
    (20,)
    >>> state_features(np.array([[OPEN_E, OPEN_W], [0, 0]])).tolist()[:8]
    [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from abco_envs.maze.rules import OPEN_BITS

__all__ = ["OBS_TYPES", "image_observation_space", "state_observation_space", "state_features"]

#: The values of the ``obs_type`` argument: a rendered RGB image, or the state vector.
OBS_TYPES = ("image", "state")


def image_observation_space(height: int, width: int) -> spaces.Box:
    """Space of ``obs_type="image"``: ``(height, width, 3)`` uint8 RGB frames."""
    return spaces.Box(0, 255, (height, width, 3), dtype=np.uint8)


def state_observation_space(n: int) -> spaces.Box:
    """Space of ``obs_type="state"``: one-hot row, one-hot col, then 4 open-side bits per cell."""
    return spaces.Box(0.0, 1.0, shape=(2 * n + 4 * n * n,), dtype=np.float32)


def state_features(cells: np.ndarray) -> np.ndarray:
    """The walls part of a state observation: per cell, 1.0 where open to N, S, E, W."""
    return ((cells[..., None] & OPEN_BITS) > 0).astype(np.float32).reshape(*cells.shape[:-2], -1)
