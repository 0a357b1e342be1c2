"""The rendered maze: layouts, their canonical pool, rendering, the env and its vector form."""

from abco_envs.maze.env import MazeEnv
from abco_envs.maze.layout import Action, InvalidLayoutError, validate_layout
from abco_envs.maze.pool import layout_pool
from abco_envs.maze.vector import MazeVectorEnv

__all__ = ["Action", "InvalidLayoutError", "MazeEnv", "MazeVectorEnv", "layout_pool",
           "validate_layout"]
