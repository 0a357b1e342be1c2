"""The maze's rules, each named once, and the one step kernel every maze steps through.

A layout is an ``(n, n)`` integer array in gym-maze's encoding: each cell holds the bits of the
sides it is open to, :data:`OPEN_N` = 1, :data:`OPEN_E` = 2, :data:`OPEN_S` = 4 and
:data:`OPEN_W` = 8. The agent starts in cell :data:`START_POSITION` ``(0, 0)`` (top-left) and
walks to :func:`goal_position` ``(n - 1, n - 1)`` (bottom-right); a move into a wall leaves it
in place. Reaching the goal pays :data:`GOAL_REWARD` and ends the episode; every other step
costs ``STEP_COST / n**2`` (see :func:`step_penalty`); episodes are cut after
:data:`MAX_EPISODE_STEPS` steps.

Stepping is a table look-up. :func:`move_table` turns layouts into the cell each action leads
to from each cell (walls applied once, at reset), and :meth:`MazeDynamics.step` looks up a
batch of ``(maze, cell, action)`` triples at once. :class:`~abco_envs.maze.env.MazeEnv` is its
one-maze case (plain integers), :class:`~abco_envs.maze.vector.MazeVectorEnv` steps all its
mazes in one call, and ``abco_data``'s random-walk reference returns walk thousands of
episodes with it. Cells are numbered row-major: ``cell = row * n + col``.

This module imports nothing else from abco, so every other module may import it.

Example:
    >>> import numpy as np
    >>> cells = np.array([[OPEN_E, OPEN_W | OPEN_S], [OPEN_E, OPEN_W | OPEN_N]])
    >>> moves = move_table(cells[None])  # one maze
    >>> dynamics = MazeDynamics(2)
    >>> dynamics.step(moves, 0, 0, Action.S)  # a wall: the agent stays in cell 0
    (np.int64(0), np.float64(-0.025), np.False_)
    >>> cell, reward, terminated = dynamics.step(moves, np.zeros(2, int), np.array([0, 1]),
    ...                                          np.array([Action.E, Action.S]))
    >>> cell.tolist(), reward.tolist(), terminated.tolist()
    ([1, 3], [-0.025, 1.0], [False, True])
"""

from __future__ import annotations

from enum import IntEnum
from typing import Any, Final

import numpy as np

__all__ = [
    "Action",
    "OPEN_N",
    "OPEN_E",
    "OPEN_S",
    "OPEN_W",
    "OPEN_BITS",
    "DELTAS",
    "START_POSITION",
    "GOAL_REWARD",
    "STEP_COST",
    "MAX_EPISODE_STEPS",
    "goal_position",
    "step_penalty",
    "episode_return",
    "optimal_return",
    "move_table",
    "MazeDynamics",
]

#: gym-maze's bit of a cell open to the north (up).
OPEN_N: Final = 1
#: gym-maze's bit of a cell open to the east (right).
OPEN_E: Final = 2
#: gym-maze's bit of a cell open to the south (down).
OPEN_S: Final = 4
#: gym-maze's bit of a cell open to the west (left).
OPEN_W: Final = 8
# Plain ints, not an IntFlag: numpy treats an IntFlag as a foreign object (int64 results and a
# scalar ``&`` about 40 times slower).


class Action(IntEnum):
    """The four moves, in gym-maze's order."""

    N = 0
    S = 1
    E = 2
    W = 3


#: gym-maze's side bits, indexed by :class:`Action`.
OPEN_BITS = np.array([OPEN_N, OPEN_S, OPEN_E, OPEN_W], dtype=np.uint8)
#: (d_row, d_col) of each action, indexed by :class:`Action`.
DELTAS = np.array([(-1, 0), (1, 0), (0, 1), (0, -1)], dtype=np.int64)
OPEN_BITS.flags.writeable = False
DELTAS.flags.writeable = False

#: Where every episode starts unless a reset option says otherwise.
START_POSITION: Final = (0, 0)
#: Reward of the step that reaches the goal (it ends the episode).
GOAL_REWARD: Final = 1.0
#: What all the steps of an ``n`` x ``n`` maze cost together, per ``n**2`` steps.
STEP_COST: Final = 0.1
#: Steps after which an episode is truncated (the registered ``max_episode_steps``).
MAX_EPISODE_STEPS: Final = 1000


def goal_position(n: int) -> tuple[int, int]:
    """The goal cell ``(row, col)`` of an ``n`` x ``n`` maze: the bottom-right corner."""
    return n - 1, n - 1


def step_penalty(n: int) -> float:
    """Reward of every step that does not reach the goal: ``-STEP_COST / n**2``."""
    return -STEP_COST / (n * n)


def episode_return(n: int, steps: np.ndarray, reached_goal: np.ndarray) -> np.ndarray:
    """Return of episodes of ``steps`` steps, the last one reaching the goal where marked.

    Args:
        n: Cells per side.
        steps: Steps each episode took (at least 1 where ``reached_goal``).
        reached_goal: Whether each episode's last step reached the goal.

    Returns:
        ``GOAL_REWARD + (steps - 1) * step_penalty(n)`` where the goal was reached, otherwise
        ``steps * step_penalty(n)``, as float64.
    """
    penalty = step_penalty(n)
    steps = np.asarray(steps)
    return np.where(reached_goal, GOAL_REWARD + (steps - 1) * penalty, steps * penalty)


def optimal_return(n: int, length: np.ndarray | int) -> np.ndarray | float:
    """Return of a shortest path of ``length`` moves: ``1 - (length - 1) * 0.1 / n**2``.

    The same quantity as :func:`episode_return` with ``reached_goal=True``, but evaluated in
    this order (it can differ from that one in the last bit): the shipped datasets store these
    bytes as their expert reference returns.
    """
    return GOAL_REWARD - (length - 1) * STEP_COST / n**2


def move_table(cells: np.ndarray) -> np.ndarray:
    """The cell each action leads to from each cell of one or many layouts.

    Args:
        cells: ``(..., n, n)`` valid layouts (see
            :func:`~abco_envs.maze.layout.validate_layout`: no side open to the outside).

    Returns:
        ``(..., n * n, 4)`` ``intp`` array: ``table[..., cell, action]`` is the row-major cell
        reached by ``action`` from ``cell``; the same cell where a wall is in the way.

    Example:
        >>> move_table(np.array([[OPEN_S, 0], [OPEN_N, 0]])).tolist()
        [[0, 2, 0, 0], [1, 1, 1, 1], [0, 2, 2, 2], [3, 3, 3, 3]]
    """
    cells = np.asarray(cells)
    n = cells.shape[-1]
    is_open = (cells.reshape(*cells.shape[:-2], n * n, 1) & OPEN_BITS) > 0
    offsets = DELTAS[:, 0] * n + DELTAS[:, 1]  # row-major cell offset of each action
    here = np.arange(n * n, dtype=np.intp)[:, None]
    return here + offsets * is_open


class MazeDynamics:
    """The step kernel of ``size`` x ``size`` mazes: a batch of moves, rewards and endings.

    Args:
        size: Cells per side.

    Attributes:
        size: Cells per side.
        goal_cell: Row-major index of the goal cell.
        step_penalty: Reward of a step that does not reach the goal.
    """

    __slots__ = ("size", "goal_cell", "step_penalty", "_arrival_reward")

    def __init__(self, size: int) -> None:
        self.size = size
        goal_row, goal_col = goal_position(size)
        self.goal_cell = goal_row * size + goal_col
        self.step_penalty = step_penalty(size)
        # The reward of a step depends only on the cell it ends in: one look-up per batch.
        self._arrival_reward = np.full(size * size, self.step_penalty)
        self._arrival_reward[self.goal_cell] = GOAL_REWARD

    def step(
        self, moves: np.ndarray, maze: Any, cell: Any, action: Any
    ) -> tuple[Any, Any, Any]:
        """Move agents one step: plain ints for one agent, equal-length arrays for many.

        Args:
            moves: ``(k, n * n, 4)`` tables from :func:`move_table`.
            maze: Which table each agent walks in (``0`` for a single maze).
            cell: Each agent's row-major cell.
            action: Each agent's :class:`Action`, already checked to be in ``0..3``.

        Returns:
            ``(next_cell, reward, terminated)``: numpy scalars or arrays like ``cell``.
        """
        next_cell = moves[maze, cell, action]
        return next_cell, self._arrival_reward[next_cell], next_cell == self.goal_cell
