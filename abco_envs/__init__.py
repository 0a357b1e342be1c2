"""abco_envs: the environments of the ABCO paper, rebuilt headless and seedable.

Importing the package registers ``AbcoMaze3x3-v0``, ``AbcoMaze5x5-v0`` and
``AbcoMaze10x10-v0`` with Gymnasium (also reachable as ``"abco_envs:AbcoMaze5x5-v0"``). It does
not import torch or pygame.

Example:
    >>> import gymnasium as gym
    >>> import abco_envs
    >>> env = gym.make("AbcoMaze3x3-v0")
    >>> env.spec.max_episode_steps
    1000
"""

from gymnasium.envs.registration import register, registry

from abco_envs.maze import Action, InvalidLayoutError, MazeEnv, MazeVectorEnv, layout_pool
from abco_envs.maze.rules import MAX_EPISODE_STEPS

__version__ = "0.1.0"

#: Maze sizes with a registered env id.
MAZE_SIZES = (3, 5, 10)
#: The registered maze ids, smallest first.
MAZE_IDS = tuple(f"AbcoMaze{n}x{n}-v0" for n in MAZE_SIZES)
#: Gymnasium's classic-control ids that abco ships experts for.
CLASSIC_IDS = ("CartPole-v1", "Acrobot-v1", "MountainCar-v0")


def maze_size(env_id: str) -> int:
    """``"AbcoMaze5x5-v0"`` (with or without ``abco_envs:``) -> 5.

    Raises:
        ValueError: ``env_id`` is not a registered abco maze.
    """
    name = env_id.split(":")[-1]
    for n, maze_id in zip(MAZE_SIZES, MAZE_IDS):
        if name == maze_id:
            return n
    raise ValueError(f"unknown maze id {env_id!r}; registered mazes: {', '.join(MAZE_IDS)}")


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
    "InvalidLayoutError",
    "MAZE_IDS",
    "MAZE_SIZES",
    "MazeEnv",
    "MazeVectorEnv",
    "layout_pool",
    "maze_size",
]
