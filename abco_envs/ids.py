"""The env ids abco knows: its registered mazes and the Gymnasium envs it has experts for.

Example:
    >>> maze_size("abco_envs:AbcoMaze5x5-v0")
    5
    >>> maze_size("AbcoMaze4x4-v0")
    Traceback (most recent call last):
    ...
    abco_envs.errors.UnknownEnvError: unknown maze id 'AbcoMaze4x4-v0'; registered mazes: AbcoMaze3x3-v0, AbcoMaze5x5-v0, AbcoMaze10x10-v0
"""  # noqa: E501

from __future__ import annotations

from abco_envs.errors import UnknownEnvError

__all__ = ["CLASSIC_IDS", "MAZE_IDS", "MAZE_SIZES", "env_name", "maze_size"]

#: Maze sizes with a registered env id.
MAZE_SIZES = (3, 5, 10)
#: The registered maze ids, smallest first.
MAZE_IDS = tuple(f"AbcoMaze{n}x{n}-v0" for n in MAZE_SIZES)
#: Gymnasium's vector-observation ids that abco ships experts for: classic control, then
#: Box2D's LunarLander (which needs the ``box2d`` extra, :mod:`abco_envs.dependencies`).
CLASSIC_IDS = ("CartPole-v1", "Acrobot-v1", "MountainCar-v0", "LunarLander-v3")


def env_name(env_id: object) -> str:
    """The id without its module prefix: ``"abco_envs:AbcoMaze5x5-v0"`` -> ``"AbcoMaze5x5-v0"``.

    Raises:
        UnknownEnvError: ``env_id`` is not a string.
    """
    if not isinstance(env_id, str):
        raise UnknownEnvError(
            f"an env id is a string such as {MAZE_IDS[0]!r}, got {env_id!r}"
            f" ({type(env_id).__name__})"
        )
    return env_id.split(":")[-1]


def is_maze(env_id: str) -> bool:
    """Whether ``env_id`` (with or without ``abco_envs:``) is one of the abco mazes: the one
    answer to that question in the project."""
    return env_name(env_id) in MAZE_IDS


def maze_size(env_id: str) -> int:
    """``"AbcoMaze5x5-v0"`` (with or without ``abco_envs:``) -> 5.

    Raises:
        UnknownEnvError: ``env_id`` is not a registered abco maze (a ``ValueError``).
    """
    name = env_name(env_id)
    for n, maze_id in zip(MAZE_SIZES, MAZE_IDS):
        if name == maze_id:
            return n
    raise UnknownEnvError(f"unknown maze id {env_id!r}; registered mazes: {', '.join(MAZE_IDS)}")
