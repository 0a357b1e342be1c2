"""The rendered maze: its rules, layouts and pool, rendering, the env and its vector form.

Modules, each importing only those above it:

- ``rules``: the rules, named once (cell bits, moves, rewards, step limit) and the step kernel;
- ``layout``: the generator, validation and shortest paths; ``pool``: the canonical layouts;
  ``procedural``: the procedural split and fresh layouts, disjoint from the pool;
- ``observation``, ``options``, ``reset``, ``render``: what both envs share;
- ``env`` (:class:`MazeEnv`) and ``vector`` (:class:`MazeVectorEnv`).
"""

from abco_envs.maze.env import MazeEnv
from abco_envs.maze.layout import Action, InvalidLayoutError, validate_layout
from abco_envs.maze.pool import layout_pool
from abco_envs.maze.procedural import fresh_layouts, procedural_layouts
from abco_envs.maze.vector import MazeVectorEnv

__all__ = ["Action", "InvalidLayoutError", "MazeEnv", "MazeVectorEnv", "fresh_layouts",
           "layout_pool", "procedural_layouts", "validate_layout"]
