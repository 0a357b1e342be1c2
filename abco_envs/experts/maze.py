"""The maze expert: a shortest path found by breadth-first search, ties broken by its own seed.

Where several shortest paths exist, each step chooses uniformly among the moves that keep the
path shortest, so experts with different seeds can walk different (equally short) paths, as
the paper's ten solutions per maze did.

Example:
    >>> from abco_envs.maze.pool import layout_pool
    >>> from abco_envs.maze.layout import shortest_path_length
    >>> cells = layout_pool(5).train[0]
    >>> actions = MazeExpert(cells, seed=0).solve()
    >>> len(actions) == shortest_path_length(cells)
    True
"""

from __future__ import annotations

from typing import Any

import numpy as np

from abco_envs.maze.layout import distances_to, validate_layout
from abco_envs.maze.rules import DELTAS, OPEN_BITS, START_POSITION, goal_position

__all__ = ["MazeExpert"]


class MazeExpert:
    """Shortest-path policy to the goal of one layout.

    As a policy for :func:`~abco_envs.experts.rollout.record_episode` it needs no layout up
    front: its ``reset(env)`` hook reads the layout the env's reset drew.

    Args:
        cells: The layout (gym-maze encoding; validated), or ``None`` to set it later.
        seed: Seed of the generator that breaks ties between equally short moves; it carries
            over from one layout to the next.
    """

    def __init__(self, cells: np.ndarray | None = None, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)
        if cells is not None:
            self.use_layout(cells)

    def use_layout(self, cells: np.ndarray) -> None:
        """Plan for ``cells``: BFS distances from every cell to the bottom-right goal."""
        self.cells = validate_layout(cells)
        self.goal = goal_position(self.cells.shape[0])
        self.dist = distances_to(self.cells, self.goal)

    def reset(self, env: Any) -> None:
        """Hook for ``record_episode``: plan for the layout ``env`` was just reset to."""
        self.use_layout(env.unwrapped.cells)

    def optimal_actions(self, row: int, col: int) -> list[int]:
        """Every move from ``(row, col)`` that starts a shortest path to the goal."""
        here = self.dist[row, col]
        return [
            a
            for a in range(4)
            if self.cells[row, col] & OPEN_BITS[a]
            and self.dist[row + DELTAS[a][0], col + DELTAS[a][1]] == here - 1
        ]

    def act(self, row: int, col: int) -> int:
        """One optimal move from ``(row, col)``; at the goal there is none (ValueError)."""
        options = self.optimal_actions(row, col)
        if not options:
            raise ValueError(f"({row}, {col}) is the goal: the expert has no move to make")
        return options[int(self.rng.integers(len(options)))] if len(options) > 1 else options[0]

    def __call__(self, obs: Any, info: dict[str, Any]) -> int:
        """Policy form: reads the agent's cell from ``info["position"]``."""
        row, col = info["position"]
        return self.act(int(row), int(col))

    def solve(self, start: tuple[int, int] = START_POSITION) -> list[int]:
        """The actions of one shortest path from ``start`` to the goal."""
        row, col = start
        actions = []
        while (row, col) != self.goal:
            a = self.act(row, col)
            actions.append(a)
            row, col = row + int(DELTAS[a][0]), col + int(DELTAS[a][1])
        return actions
