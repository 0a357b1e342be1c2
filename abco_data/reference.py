"""Reference returns: what an expert and a random policy score, for Performance ``P``.

``P = (R - random) / (expert - random)``. For mazes both references are per layout (the paper
normalised per maze) and cover the ``train`` and ``test`` splits:

- expert: the optimal return ``1 - (L - 1) * 0.1 / n**2`` of the layout's shortest path ``L``;
- random: the mean return of uniformly random actions over ``episodes`` seeded episodes with
  the env's 1000-step cap, computed by a vectorised walk that applies the env's rules (a move
  into a wall stays put, +1 at the goal, ``-0.1 / n**2`` per other step).

For classic control, both are means over seeded episodes of the env itself.

Example:
    >>> ref = maze_reference(3, episodes=20)
    >>> len(ref.layout_ids), bool(ref.expert_mean > ref.random_mean)
    (200, True)
    >>> round(ref.performance(ref.expert_mean), 6)
    1.0
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from abco_envs.maze.rules import MAX_EPISODE_STEPS

__all__ = ["ReferenceReturns", "maze_reference", "classic_reference", "REFERENCE_SEED"]

#: Seed root of every reference computation (independent of the datasets' seeds).
REFERENCE_SEED = 12345
#: The maze's step limit, which caps every random walk (the env's own rule).
MAZE_MAX_STEPS = MAX_EPISODE_STEPS


@dataclass(frozen=True, eq=False)
class ReferenceReturns:
    """Expert and random reference returns of one environment.

    Attributes:
        expert_mean: Mean expert return (mazes: over the train split's layouts).
        random_mean: Mean random-policy return (mazes: over the train split's layouts).
        layout_ids: Mazes: structural ids of the train then the test layouts; else ``None``.
        layout_splits: Mazes: ``"train"`` or ``"test"`` for each entry of ``layout_ids``.
        expert_per_layout: Mazes: optimal return of each layout; else ``None``.
        random_per_layout: Mazes: mean random return on each layout; else ``None``.
    """

    expert_mean: float
    random_mean: float
    layout_ids: tuple[str, ...] | None = None
    layout_splits: tuple[str, ...] | None = None
    expert_per_layout: np.ndarray | None = None
    random_per_layout: np.ndarray | None = None

    def performance(self, episode_return: float, layout_id: str | None = None) -> float:
        """``P`` of one return, normalised on ``layout_id``'s references when given."""
        expert, random = self.expert_mean, self.random_mean
        if layout_id is not None:
            if self.layout_ids is None or layout_id not in self.layout_ids:
                raise KeyError(f"no reference returns for layout {layout_id!r}")
            i = self.layout_ids.index(layout_id)
            expert = float(self.expert_per_layout[i])  # type: ignore[index]
            random = float(self.random_per_layout[i])  # type: ignore[index]
        return (float(episode_return) - random) / (expert - random)


def _random_walk_returns(cells: np.ndarray, episodes: int, seed: int) -> np.ndarray:
    """Mean return of ``episodes`` uniform random walks on each layout of ``cells`` (k, n, n)."""
    from abco_envs.maze.rules import MazeDynamics, episode_return, move_table

    k, n = cells.shape[0], cells.shape[1]
    rng = np.random.default_rng([REFERENCE_SEED, seed, n])
    dynamics, moves = MazeDynamics(n), move_table(cells)
    layout = np.repeat(np.arange(k), episodes)
    cell = np.zeros(layout.size, dtype=np.intp)  # every walk starts in cell (0, 0)
    hit = np.zeros(layout.size, dtype=np.int64)  # step at which the goal was reached, 0 = never
    active = np.arange(layout.size)
    for t in range(1, MAZE_MAX_STEPS + 1):
        a = rng.integers(4, size=active.size)
        cell[active], _, done = dynamics.step(moves, layout[active], cell[active], a)
        hit[active[done]] = t
        active = active[~done]
        if not active.size:
            break
    returns = episode_return(n, np.where(hit > 0, hit, MAZE_MAX_STEPS), hit > 0)
    return returns.reshape(k, episodes).mean(axis=1)


@lru_cache(maxsize=16)
def maze_reference(size: int, episodes: int = 100) -> ReferenceReturns:
    """Per-layout references of the ``size`` x ``size`` maze over its train and test splits."""
    from abco_envs.maze.layout import shortest_path_length
    from abco_envs.maze.pool import layout_pool
    from abco_envs.maze.rules import optimal_return

    pool = layout_pool(size)
    ids, splits, expert, random = [], [], [], []
    for split_no, name in enumerate(("train", "test")):
        cells = pool.split(name)
        if not len(cells):
            continue
        lengths = np.array([shortest_path_length(c) for c in cells], dtype=np.float64)
        expert.append(optimal_return(size, lengths))
        random.append(_random_walk_returns(np.asarray(cells), episodes, split_no))
        ids.extend(pool.ids(name))
        splits.extend([name] * len(cells))
    expert_arr, random_arr = np.concatenate(expert), np.concatenate(random)
    train = np.array(splits) == "train"
    for arr in (expert_arr, random_arr):
        arr.flags.writeable = False
    return ReferenceReturns(
        expert_mean=float(expert_arr[train].mean()), random_mean=float(random_arr[train].mean()),
        layout_ids=tuple(ids), layout_splits=tuple(splits),
        expert_per_layout=expert_arr, random_per_layout=random_arr,
    )


def _mean_return(env_id: str, policy_for_episode, episodes: int, seed: int) -> float:
    import gymnasium as gym

    env = gym.make(env_id)
    total = 0.0
    for i in range(episodes):
        policy = policy_for_episode(env, seed + i)
        obs, info = env.reset(seed=seed + i)
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            total += float(reward)
            done = terminated or truncated
    env.close()
    return total / episodes


@lru_cache(maxsize=16)
def classic_reference(env_id: str, episodes: int = 100, expert_episodes: int = 20
                      ) -> ReferenceReturns:
    """Mean returns of the expert and of uniform random actions on a classic-control env."""
    from abco_envs.experts import RandomPolicy, expert_policy

    random = _mean_return(env_id, lambda env, s: RandomPolicy(env.action_space, seed=s),
                          episodes, REFERENCE_SEED)
    expert = _mean_return(env_id, lambda env, s: expert_policy(env_id, seed=s),
                          expert_episodes, REFERENCE_SEED + 10_000)
    return ReferenceReturns(expert_mean=expert, random_mean=random)
