"""MiniGrid for abco: the env under an id of your own, and its expert (docs/examples/minigrid.md).

MiniGrid's observations are a Dict (the agent's view, its direction, the mission's text);
abco trains on an image, so the env is wrapped in ``ImgObsWrapper`` (the 7x7x3 symbolic
view: object, colour and state of each cell ahead of the agent) and registered here as
``GridEmpty-v0``. ``--env minigrid_example:GridEmpty-v0`` imports this module first.
"""

import gymnasium as gym
import numpy as np
from minigrid.core.constants import OBJECT_TO_IDX
from minigrid.wrappers import ImgObsWrapper

LEFT, RIGHT, FORWARD = 0, 1, 2  # MiniGrid's actions
GOAL, WALL = OBJECT_TO_IDX["goal"], OBJECT_TO_IDX["wall"]


def grid_image(**kwargs):
    """A 5x5 room, random start, the goal in a corner; seen as its 7x7x3 view."""
    return ImgObsWrapper(gym.make("MiniGrid-Empty-Random-5x5-v0", **kwargs))


if "GridEmpty-v0" not in gym.registry:
    gym.register("GridEmpty-v0", entry_point=grid_image, max_episode_steps=100)


def expert(obs):
    """Walk to the goal, seen in the view: the agent stands at (3, 6), facing row 0."""
    goals = np.argwhere(obs[:, :, 0] == GOAL)  # (column, row) of the goal in the view
    if len(goals) == 0:
        return RIGHT  # behind the agent: turn to see it
    column, row = goals[0]
    if column == 3 or (row < 6 and obs[3, 5, 0] != WALL):
        return FORWARD  # straight ahead, or walk level with it first
    return LEFT if column < 3 else RIGHT
