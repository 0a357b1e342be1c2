"""Reference returns: what an expert and a random policy score, for Performance ``P``.

``P = (R - random) / (expert - random)``. For mazes both references are per layout (the paper
normalised per maze); a dataset's cover the pool's ``train`` and ``test`` splits
(:func:`maze_reference`), and :func:`layout_reference` computes them, the same way, for any
other layouts (the procedural layouts a run trains on, fresh layouts: :func:`fresh_reference`):

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
    >>> fresh = fresh_reference(5, 3, seed=0, episodes=20)
    >>> fresh.layout_splits, fresh.layout_ids == fresh_reference(5, 3, seed=0, episodes=20).layout_ids
    (('fresh', 'fresh', 'fresh'), True)
    >>> len(ref.extended(fresh).layout_ids)
    203
"""  # noqa: E501

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from abco_envs.maze.rules import MAX_EPISODE_STEPS

__all__ = ["ReferenceReturns", "maze_reference", "layout_reference", "fresh_reference",
           "classic_reference", "protocol_reference", "REFERENCE_SEED", "REFERENCE_EPISODES",
           "PAPER_MAX_VISITS", "PAPER_FAIL_RETURN"]

#: Seed root of every reference computation (independent of the datasets' seeds).
REFERENCE_SEED = 12345
#: Random episodes per layout of the random reference (the published datasets' value).
REFERENCE_EPISODES = 100
#: Random-walk streams of :func:`layout_reference` (the pool's splits use 0 and 1).
_LAYOUT_STREAM = 2
#: The maze's step limit, which caps every random walk (the env's own rule).
MAZE_MAX_STEPS = MAX_EPISODE_STEPS
#: The paper protocol's rule (the authors' evaluation): the 4th visit of a cell ends the
#: episode, unsuccessful, with this return.
PAPER_MAX_VISITS = 4
PAPER_FAIL_RETURN = -1.0
#: Random-walk stream of :func:`protocol_reference` (apart from the pool's and the layouts').
_PROTOCOL_STREAM = 3
#: Evaluation protocols :func:`protocol_reference` measures under.
PROTOCOLS = ("paper", "standard")


@dataclass(frozen=True, eq=False)
class ReferenceReturns:
    """Expert and random reference returns of one environment.

    Attributes:
        expert_mean: Mean expert return (mazes: over the train split's layouts).
        random_mean: Mean random-policy return (mazes: over the train split's layouts).
        layout_ids: Mazes: structural ids of the layouts (a dataset's: the train then the test
            split); else ``None``.
        layout_splits: Mazes: where each entry of ``layout_ids`` comes from (a dataset's:
            ``"train"`` or ``"test"``; :func:`layout_reference`'s: its ``split`` argument).
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
            ids, experts, randoms = self.layout_ids, self.expert_per_layout, self.random_per_layout
            if ids is None or experts is None or randoms is None or layout_id not in ids:
                raise KeyError(f"no reference returns for layout {layout_id!r}")
            i = ids.index(layout_id)
            expert, random = float(experts[i]), float(randoms[i])
        return (float(episode_return) - random) / (expert - random)

    def extended(self, other: ReferenceReturns) -> ReferenceReturns:
        """These references plus ``other``'s layouts that are not here yet (mazes).

        The means stay this one's; a layout in both keeps this one's references.

        Raises:
            ValueError: Either holds no per-layout references.
        """
        if self.layout_ids is None or other.layout_ids is None:
            raise ValueError("only per-layout (maze) references can be extended")
        known = set(self.layout_ids)
        new = [i for i, lid in enumerate(other.layout_ids) if lid not in known]
        if not new:
            return self
        splits = other.layout_splits or ("",) * len(other.layout_ids)
        expert = np.concatenate([np.asarray(self.expert_per_layout),
                                 np.asarray(other.expert_per_layout)[new]])
        random = np.concatenate([np.asarray(self.random_per_layout),
                                 np.asarray(other.random_per_layout)[new]])
        for arr in (expert, random):
            arr.flags.writeable = False
        return ReferenceReturns(
            expert_mean=self.expert_mean, random_mean=self.random_mean,
            layout_ids=self.layout_ids + tuple(other.layout_ids[i] for i in new),
            layout_splits=(self.layout_splits or ("",) * len(self.layout_ids))
            + tuple(splits[i] for i in new),
            expert_per_layout=expert, random_per_layout=random,
        )


def _random_walk_returns(cells: np.ndarray, episodes: int, seed: int | tuple[int, ...],
                         protocol: str = "standard", max_steps: int | None = None
                         ) -> np.ndarray:  # fmt: skip
    """Mean return of ``episodes`` uniform random walks on each layout of ``cells`` (k, n, n),
    drawn from the generator ``[REFERENCE_SEED, *seed, n]``.

    ``protocol`` ``"standard"`` applies the env's rules; ``"paper"`` also ends a walk with
    return :data:`PAPER_FAIL_RETURN` when it enters (or stays in) one cell for the
    :data:`PAPER_MAX_VISITS`-th time, the start counting as the first visit (the evaluation's
    rule, :mod:`abco_train.harness.rollouts`). ``max_steps`` caps the walks below the env's own
    limit, as the evaluation's ``eval_max_steps`` does.
    """
    from abco_envs.maze.rules import MazeDynamics, episode_return, move_table

    k, n = cells.shape[0], cells.shape[1]
    stream = list(seed) if isinstance(seed, tuple) else [seed]
    rng = np.random.default_rng([REFERENCE_SEED, *stream, n])
    dynamics, moves = MazeDynamics(n), move_table(cells)
    cap = MAZE_MAX_STEPS if max_steps is None else min(MAZE_MAX_STEPS, int(max_steps))
    layout = np.repeat(np.arange(k), episodes)
    cell = np.zeros(layout.size, dtype=np.intp)  # every walk starts in cell (0, 0)
    hit = np.zeros(layout.size, dtype=np.int64)  # step at which the goal was reached, 0 = never
    looped = np.zeros(layout.size, dtype=bool)
    visits = np.zeros((layout.size, n * n), dtype=np.int16) if protocol == "paper" else None
    if visits is not None:
        visits[:, 0] = 1
    active = np.arange(layout.size)
    for t in range(1, cap + 1):
        a = rng.integers(4, size=active.size)
        cell[active], _, done = dynamics.step(moves, layout[active], cell[active], a)
        hit[active[done]] = t
        ended = done
        if visits is not None:
            visits[active, cell[active]] += 1
            loop = (visits[active, cell[active]] >= PAPER_MAX_VISITS) & ~done
            looped[active[loop]] = True
            ended = done | loop
        active = active[~ended]
        if not active.size:
            break
    returns = episode_return(n, np.where(hit > 0, hit, cap), hit > 0)
    returns[looped] = PAPER_FAIL_RETURN
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


def layout_reference(cells: np.ndarray, split: str = "layouts", *,
                     episodes: int = REFERENCE_EPISODES, stream: int = 0) -> ReferenceReturns:
    """Per-layout references of any maze layouts, computed as the datasets' are.

    The expert return of a layout is its optimal return (shortest path); the random one the
    mean return of ``episodes`` uniform random walks from ``(0, 0)`` with the 1000-step cap,
    all layouts' walks drawn from one generator (``[REFERENCE_SEED, 2, stream, n]``, apart
    from the pool's), so the numbers are fixed by the layouts, their order, ``episodes`` and
    ``stream``. About 1 s for 100 5x5 or 10x10 layouts at 100 episodes.

    Args:
        cells: ``(k, n, n)`` layouts (k >= 1).
        split: The name stored in ``layout_splits`` for each (e.g. ``"fresh"``).
        episodes: Random walks per layout.
        stream: Another stream of random walks for another set of layouts.

    Returns:
        References whose means are over these layouts.

    Raises:
        ValueError: No layouts, or not a stack of square layouts.
    """
    from abco_envs.maze.layout import shortest_path_length
    from abco_envs.maze.rules import optimal_return

    cells = _layout_stack(cells)
    size = cells.shape[1]
    lengths = np.array([shortest_path_length(c) for c in cells], dtype=np.float64)
    expert = np.asarray(optimal_return(size, lengths), dtype=np.float64)
    random = _random_walk_returns(cells, episodes, (_LAYOUT_STREAM, int(stream)))
    return _per_layout(cells, split, expert, random)


@lru_cache(maxsize=16)
def fresh_reference(size: int, count: int, seed: int = 0,
                    episodes: int = REFERENCE_EPISODES) -> ReferenceReturns:  # fmt: skip
    """References of :func:`abco_envs.fresh_layouts` ``(size, count, seed)`` (cached per
    process); their walks are stream ``1 + seed`` of :func:`layout_reference`."""
    from abco_envs.maze.procedural import fresh_layouts

    return layout_reference(fresh_layouts(size, count, seed), "fresh", episodes=episodes,
                            stream=1 + int(seed))


def protocol_reference(cells: np.ndarray, protocol: str, max_steps: int | None = None, *,
                       split: str = "layouts", episodes: int = REFERENCE_EPISODES
                       ) -> ReferenceReturns:  # fmt: skip
    """Per-layout references of ``cells`` measured under an evaluation protocol: the ones the
    normalised score divides by.

    The random return of a layout is the mean of ``episodes`` uniform random walks from
    ``(0, 0)`` under ``protocol`` (``"paper"``: the 4th visit of a cell ends the walk at
    :data:`PAPER_FAIL_RETURN`; ``"standard"``: the env's rules) and the step cap ``max_steps``
    (``None``: the env's 1000 steps), drawn from a stream of their own
    (``[REFERENCE_SEED, 3, protocol, n]``, never an evaluation's seed). The expert return is
    the shortest path's under the same cap (the expert never revisits a cell, so both
    protocols agree).

    Example:
        >>> from abco_envs.maze.pool import layout_pool
        >>> cells = layout_pool(3).split("train")[:5]
        >>> paper = protocol_reference(cells, "paper", episodes=50)
        >>> standard = protocol_reference(cells, "standard", episodes=50)
        >>> bool(paper.random_mean < standard.random_mean)
        True
        >>> paper.expert_mean == standard.expert_mean
        True

    Raises:
        ValueError: An unknown protocol, no layouts, or not a stack of square layouts.
    """
    from abco_envs.maze.layout import shortest_path_length
    from abco_envs.maze.rules import episode_return

    if protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; expected one of {PROTOCOLS}")
    cells = _layout_stack(cells)
    size = cells.shape[1]
    cap = MAZE_MAX_STEPS if max_steps is None else min(MAZE_MAX_STEPS, int(max_steps))
    lengths = np.array([shortest_path_length(c) for c in cells], dtype=np.int64)
    expert = episode_return(size, np.minimum(lengths, cap), lengths <= cap).astype(np.float64)
    random = _random_walk_returns(cells, episodes, (_PROTOCOL_STREAM, PROTOCOLS.index(protocol)),
                                  protocol, cap)  # fmt: skip
    return _per_layout(cells, split, expert, random)


def _layout_stack(cells: np.ndarray) -> np.ndarray:
    cells = np.asarray(cells)
    if cells.ndim != 3 or cells.shape[1] != cells.shape[2] or not len(cells):
        raise ValueError(f"expected a (k, n, n) stack of k >= 1 layouts, got {cells.shape}")
    return cells


def _per_layout(cells: np.ndarray, split: str, expert: np.ndarray,
                random: np.ndarray) -> ReferenceReturns:  # fmt: skip
    """References whose means are over ``cells``, the per-layout arrays frozen."""
    from abco_envs.maze.layout import layout_hash

    for arr in (expert, random):
        arr.flags.writeable = False
    return ReferenceReturns(
        expert_mean=float(expert.mean()), random_mean=float(random.mean()),
        layout_ids=tuple(layout_hash(c) for c in cells), layout_splits=(split,) * len(cells),
        expert_per_layout=expert, random_per_layout=random,
    )


def _mean_return(env_id: str, policy_for_episode, episodes: int, seed: int,
                 max_steps: int | None = None) -> float:  # fmt: skip
    import gymnasium as gym

    env = gym.make(env_id)
    total = 0.0
    for i in range(episodes):
        policy = policy_for_episode(env, seed + i)
        obs, info = env.reset(seed=seed + i)
        done, steps = False, 0
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            total += float(reward)
            steps += 1
            done = terminated or truncated or (max_steps is not None and steps >= max_steps)
    env.close()
    return total / episodes


@lru_cache(maxsize=16)
def classic_reference(env_id: str, episodes: int = 100, expert_episodes: int = 20,
                      max_steps: int | None = None) -> ReferenceReturns:  # fmt: skip
    """Mean returns of the expert and of uniform random actions on a classic-control env
    (episodes capped at ``max_steps`` when given, as an evaluation's ``eval_max_steps``)."""
    from abco_envs import check_env_dependencies
    from abco_envs.experts import RandomPolicy, expert_policy

    check_env_dependencies(env_id)  # LunarLander without Box2D: one line naming the extra
    random = _mean_return(env_id, lambda env, s: RandomPolicy(env.action_space, seed=s),
                          episodes, REFERENCE_SEED, max_steps)
    expert = _mean_return(env_id, lambda env, s: expert_policy(env_id, seed=s),
                          expert_episodes, REFERENCE_SEED + 10_000, max_steps)
    return ReferenceReturns(expert_mean=expert, random_mean=random)
