"""abco_envs: the environments of the ABCO paper, rebuilt headless and seedable.

Importing the package registers ``AbcoMaze3x3-v0``, ``AbcoMaze5x5-v0`` and
``AbcoMaze10x10-v0`` with Gymnasium (also reachable as ``"abco_envs:AbcoMaze5x5-v0"``). It does
not import torch or pygame. Beside the mazes abco works with Gymnasium's CartPole-v1,
Acrobot-v1, MountainCar-v0 and LunarLander-v3 (:data:`CLASSIC_IDS`; LunarLander needs the
``box2d`` extra, :func:`check_env_dependencies`); :data:`SUCCESS_RULES` says when an episode of
each counts as a success.

Example:
    >>> import gymnasium as gym
    >>> import abco_envs
    >>> env = gym.make("AbcoMaze3x3-v0")
    >>> env.spec.max_episode_steps
    1000
"""

from gymnasium.envs.registration import register, registry

from abco_envs.dependencies import check_env_dependencies
from abco_envs.errors import (
    InvalidActionError,
    InvalidLayoutError,
    InvalidOptionError,
    MissingDependencyError,
    OptionOutOfRangeError,
    UnknownEnvError,
)
from abco_envs.ids import CLASSIC_IDS, MAZE_IDS, MAZE_SIZES, env_name, is_maze, maze_size
from abco_envs.maze import (
    Action,
    MazeEnv,
    MazeVectorEnv,
    fresh_layouts,
    layout_pool,
    procedural_layouts,
)
from abco_envs.maze.rules import MAX_EPISODE_STEPS
from abco_envs.success import SUCCESS_RULES, SuccessRule, is_success, success_mask

__version__ = "0.1.0"

for _n, _id in zip(MAZE_SIZES, MAZE_IDS):
    if _id not in registry:
        register(
            id=_id,
            entry_point="abco_envs.maze.env:MazeEnv",
            vector_entry_point="abco_envs.maze.vector:MazeVectorEnv",
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs={"size": _n},
        )

__all__ = [
    "Action",
    "CLASSIC_IDS",
    "InvalidActionError",
    "InvalidLayoutError",
    "InvalidOptionError",
    "MAZE_IDS",
    "MAZE_SIZES",
    "MazeEnv",
    "MazeVectorEnv",
    "MissingDependencyError",
    "OptionOutOfRangeError",
    "SUCCESS_RULES",
    "SuccessRule",
    "UnknownEnvError",
    "check_env_dependencies",
    "env_name",
    "fresh_layouts",
    "is_maze",
    "is_success",
    "layout_pool",
    "maze_size",
    "procedural_layouts",
    "success_mask",
]
