"""Evaluation rollouts, batched through a vector env with one forward pass per step.

Every evaluation episode runs in its own slot of a vector env: for mazes a
:class:`~abco_envs.maze.MazeVectorEnv` with one slot per layout of the split (``layout_index``
``0..k-1``, start ``(0, 0)``) or per layout given (``layouts``: the training layouts of a run
on procedural data, fresh layouts), for classic control a ``SyncVectorEnv`` reset with seeds
``seed + i``. Each step calls the policy once on the observations of every episode still
running. The rollouts double as ABCO's post-demonstrations ``I_pos``: with ``record=True``
every run's observations and actions are kept.

Protocols (mazes):

* ``standard``: the env's own rules (goal, or truncation after 1000 steps).
* ``paper``: the authors' evaluation rule: the reset cell counts as the first visit, and the
  episode ends, unsuccessful, with return **-1** as soon as the agent enters (or stays in) a
  cell for the 4th time. A policy stuck against a wall thus stops after 3 steps.

Classic control always uses the env's rules; ``paper`` changes nothing there.

Goals (``v_e``): maze, the goal cell reached (terminated); CartPole, 195 steps survived;
MountainCar and Acrobot, the env's own termination.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import abco_envs
from abco_train.config.run import PROTOCOLS, env_kind
from abco_train.harness.metrics import performance, summarize

__all__ = ["PROTOCOLS", "Rollouts", "rollout", "score", "CARTPOLE_GOAL_STEPS"]


CARTPOLE_GOAL_STEPS = 195
PAPER_MAX_VISITS = 4
PAPER_FAIL_RETURN = -1.0

ActFn = Callable[[np.ndarray], np.ndarray]


@dataclass
class Rollouts:
    """The outcome of a batch of evaluation episodes.

    Attributes:
        returns: ``(E,)`` episode returns (``-1`` for a ``paper``-protocol failure).
        successes: ``(E,)`` ``v_e``: the goal was reached.
        lengths: ``(E,)`` number of steps.
        layout_indices: ``(E,)`` maze layout of each episode in its split, else ``None``.
        layout_ids: Structural id of each episode's layout, else ``None``.
        observations: With ``record``: every run's ``T_e + 1`` observations, run after run.
        actions: With ``record``: ``(M,)`` the policy's actions, ``M = sum T_e``.
        obs_t: With ``record``: row of ``s_t`` of each transition in ``observations``.
        run_ids: With ``record``: run of each transition.
        paths: Mazes: each run's ``(T_e + 1, 2)`` cells.
    """

    returns: np.ndarray
    successes: np.ndarray
    lengths: np.ndarray
    layout_indices: np.ndarray | None = None
    layout_ids: list[str] | None = None
    observations: np.ndarray | None = None
    actions: np.ndarray | None = None
    obs_t: np.ndarray | None = None
    run_ids: np.ndarray | None = None
    paths: list[np.ndarray] | None = None

    @property
    def win_rate(self) -> float:
        """``P(g | E)``."""
        return float(self.successes.mean()) if len(self.successes) else 0.0


def make_vector_env(env_id: str, num_envs: int, env_kwargs: dict[str, Any]) -> gym.vector.VectorEnv:
    """The vector env of ``num_envs`` slots (mazes: MazeVectorEnv; others: SyncVectorEnv)."""
    if env_kind(env_id) == "maze":
        return gym.make_vec(
            env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **env_kwargs
        )
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync", **env_kwargs)


def rollout(
    act: ActFn,
    env_id: str,
    *,
    episodes: int | None = None,
    split: str = "train",
    env_kwargs: dict[str, Any] | None = None,
    seed: int = 0,
    protocol: str = "paper",
    record: bool = False,
    max_steps: int | None = None,
    layouts: np.ndarray | None = None,
) -> Rollouts:
    """Run ``act`` on a batch of episodes, one policy call per step for all of them.

    Args:
        act: Batched greedy policy: ``(B, *obs_shape)`` observations -> ``(B,)`` actions.
        env_id: Gymnasium id.
        episodes: Mazes: evaluate the first ``episodes`` layouts of ``split`` or of
            ``layouts`` (default: all); classic control: number of episodes (default 100).
        split: Maze split, ``"train"`` or ``"test"`` (ignored with ``layouts``).
        env_kwargs: Extra env arguments (mazes: ``obs_type``, ``image_size``).
        seed: Reset seed (episode ``i`` gets ``seed + i``).
        protocol: ``"standard"`` or ``"paper"`` (see module docstring).
        record: Keep observations and actions (post-demonstrations).
        max_steps: End episodes (unsuccessful unless the goal was reached on that step)
            after this many steps; default the env's own limit.
        layouts: Mazes: ``(k, n, n)`` layouts to evaluate on, one episode each (the
            ``layout`` reset option), instead of a split's; their ``layout_indices`` are -1.
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; expected one of {PROTOCOLS}")
    maze = env_kind(env_id) == "maze"
    kwargs = dict(env_kwargs or {})
    options: dict[str, Any] = {}
    if maze:
        n = abco_envs.maze_size(env_id)
        given = layouts is not None
        available = len(layouts) if given else len(abco_envs.layout_pool(n).split(split))
        num = available if episodes is None else min(int(episodes), available)
        kwargs["split"] = "train" if given else split
        options = ({"layout": np.asarray(layouts)[:num]} if given
                   else {"layout_index": list(range(num))})  # fmt: skip
        options["start"] = np.zeros((num, 2), dtype=int)
    else:
        num = 100 if episodes is None else int(episodes)
    envs = make_vector_env(env_id, num, kwargs)
    obs, info = envs.reset(seed=seed, options=options or None)

    returns = np.zeros(num)
    lengths = np.zeros(num, dtype=np.int64)
    successes = np.zeros(num, dtype=bool)
    done = np.zeros(num, dtype=bool)
    layout_indices = np.asarray(info["layout_index"]).copy() if maze else None
    layout_ids = [str(x) for x in info["layout_id"]] if maze else None
    paper = maze and protocol == "paper"
    if maze:
        visits = np.zeros((num, n * n), dtype=np.int64)
        cells = info["position"][:, 0] * n + info["position"][:, 1]
        visits[np.arange(num), cells] = 1
    first_obs = obs.copy() if record else None
    first_pos = info["position"].copy() if maze else None
    steps: list[tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray | None]] = []

    while not done.all():
        active = np.flatnonzero(~done)
        actions = np.zeros(num, dtype=np.int64)
        actions[active] = np.asarray(act(obs[active])).reshape(-1)
        obs, rewards, terminated, truncated, info = envs.step(actions)
        returns[active] += rewards[active]
        lengths[active] += 1
        ended = (terminated | truncated)[active]
        if maze:
            successes[active] = terminated[active]
            pos = info["position"][active]
            if paper:
                cells = pos[:, 0] * n + pos[:, 1]
                visits[active, cells] += 1
                looped = (visits[active, cells] >= PAPER_MAX_VISITS) & ~terminated[active]
                returns[active[looped]] = PAPER_FAIL_RETURN
                ended |= looped
        elif abco_envs.env_name(env_id) == "CartPole-v1":
            successes[active] = lengths[active] >= CARTPOLE_GOAL_STEPS
        else:
            successes[active] = terminated[active]
        if max_steps is not None:
            ended |= lengths[active] >= max_steps
        steps.append((
            active,
            obs[active].copy() if record else None,
            actions[active],
            info["position"][active].copy() if maze else None,
        ))  # fmt: skip
        done[active[ended]] = True
    envs.close()

    out = Rollouts(returns, successes, lengths, layout_indices, layout_ids)
    if maze:
        out.paths = _per_run(num, first_pos, [(a, p) for a, _, _, p in steps])
    if record:
        run_obs = _per_run(num, first_obs, [(a, o) for a, o, _, _ in steps])
        run_acts = _per_run(num, None, [(a, x) for a, _, x, _ in steps])
        starts = np.concatenate([[0], np.cumsum(lengths + 1)[:-1]])
        out.observations = np.concatenate(run_obs)
        out.actions = np.concatenate(run_acts).astype(np.int64)
        out.run_ids = np.repeat(np.arange(num), lengths)
        out.obs_t = np.concatenate([s + np.arange(t) for s, t in zip(starts, lengths)])
    return out


def _per_run(
    num: int, first: np.ndarray | None, steps: list[tuple[np.ndarray, np.ndarray]]
) -> list[np.ndarray]:
    """Regroup per-step rows of the active runs into one array per run (time order kept)."""
    runs = np.concatenate([a for a, _ in steps])
    rows = np.concatenate([x for _, x in steps])
    order = np.argsort(runs, kind="stable")
    bounds = np.searchsorted(runs[order], np.arange(num + 1))
    grouped = [rows[order[bounds[e] : bounds[e + 1]]] for e in range(num)]
    if first is None:
        return grouped
    return [np.concatenate([first[e : e + 1], g]) for e, g in enumerate(grouped)]


def score(rollouts: Rollouts, reference: Any, per_episode: bool = False) -> dict[str, Any]:
    """AER, ``P`` (per episode against its own references, then averaged) and success rate.

    Args:
        rollouts: The episodes.
        reference: A :class:`abco_data.ReferenceReturns` (per layout for mazes).
        per_episode: Also list every episode's return and ``P`` (``episode_returns``,
            ``episode_performance``), for confidence intervals over episodes.
    """
    if rollouts.layout_ids is not None and reference.layout_ids is not None:
        where = {lid: i for i, lid in enumerate(reference.layout_ids)}
        missing = [lid for lid in rollouts.layout_ids if lid not in where]
        if missing:
            raise KeyError(f"no reference returns for layouts {missing[:3]}...")
        idx = np.array([where[lid] for lid in rollouts.layout_ids])
        expert = np.asarray(reference.expert_per_layout)[idx]
        random = np.asarray(reference.random_per_layout)[idx]
    else:
        expert, random = reference.expert_mean, reference.random_mean
    out: dict[str, Any] = summarize(rollouts.returns, rollouts.successes, expert, random)
    out["mean_length"] = float(rollouts.lengths.mean())
    if per_episode:
        out["episode_returns"] = np.asarray(rollouts.returns, dtype=np.float64).tolist()
        out["episode_performance"] = performance(rollouts.returns, expert, random).tolist()
    return out
