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

Goals (``v_e``): each env's rule in :data:`abco_envs.SUCCESS_RULES` (maze, the goal cell
reached; CartPole, 195 steps survived; MountainCar and Acrobot, the env's own termination;
LunarLander, a return of at least 200 at the end of the episode; an env whose ``info`` reports
``is_success``, that).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import abco_envs
from abco_data.generation.reference import PAPER_FAIL_RETURN, PAPER_MAX_VISITS
from abco_train.config.run import PROTOCOLS, env_kind
from abco_train.harness.metrics import performance, summarize

__all__ = ["PROTOCOLS", "Rollouts", "rollout", "score", "CARTPOLE_GOAL_STEPS"]


CARTPOLE_GOAL_STEPS = int(abco_envs.SUCCESS_RULES["CartPole-v1"].threshold)

ActFn = Callable[..., np.ndarray]  # (obs) -> actions; with ``reads_info``: (obs, info)


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
        budget_cut: With ``max_total_steps``: ``(E,)`` the runs it ended unfinished.
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
    budget_cut: np.ndarray | None = None

    @property
    def win_rate(self) -> float:
        """``P(g | E)`` over the runs that ended on their own: a run the budget cut
        unfinished says nothing of the policy's chance to reach the goal (0 if none ended).

        Example:
            >>> runs = Rollouts(returns=np.zeros(4), successes=np.array([1, 0, 0, 0], bool),
            ...                 lengths=np.ones(4), budget_cut=np.array([0, 0, 1, 1], bool))
            >>> runs.win_rate
            0.5
        """
        ended = self.successes if self.budget_cut is None else self.successes[~self.budget_cut]
        return float(ended.mean()) if len(ended) else 0.0


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
    max_total_steps: int | None = None,
) -> Rollouts:
    """Run ``act`` on a batch of episodes, one policy call per step for all of them.

    Args:
        act: Batched greedy policy: ``(B, *obs_shape)`` observations -> ``(B,)`` actions; one
            with a true ``reads_info`` attribute is called ``act(obs, info)`` with the
            episodes' per-episode ``info`` entries too (a reference policy: the expert).
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
        max_total_steps: Stop the batch when its episodes' steps add up to this many (a
            learner's interaction budget, at least 1): the runs still going end there
            (``budget_cut``), unsuccessful unless their goal was already reached; where fewer
            steps are left than runs going, the runs of lower index take them.
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; expected one of {PROTOCOLS}")
    if max_total_steps is not None and max_total_steps < 1:
        raise ValueError(f"max_total_steps must be at least 1, got {max_total_steps}")
    num, kwargs, options = _episodes(env_id, episodes, split, env_kwargs, layouts)
    envs = make_vector_env(env_id, num, kwargs)
    reads_info = bool(getattr(act, "reads_info", False))  # a reference policy (the expert)
    obs, info = envs.reset(seed=seed, options=options or None)
    tally = _Tally.start(env_id, num, info, paper=protocol == "paper")
    first_obs = obs.copy() if record else None
    steps: list[tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray | None]] = []
    cut = np.zeros(num, dtype=bool)
    while not tally.done.all():
        active = np.flatnonzero(~tally.done)
        if max_total_steps is not None:  # the steps left go to the runs of lower index
            left = max(0, max_total_steps - int(tally.lengths.sum()))
            cut[active[left:]] = tally.done[active[left:]] = True
            active = active[:left]
            if not len(active):
                break
        actions = np.zeros(num, dtype=np.int64)
        chosen = act(obs[active], _rows(info, active, num)) if reads_info else act(obs[active])
        actions[active] = np.asarray(chosen).reshape(-1)
        obs, rewards, terminated, truncated, info = envs.step(actions)
        ended = tally.step(active, rewards, terminated, truncated, info, max_steps)
        steps.append((
            active,
            obs[active].copy() if record else None,
            actions[active],
            info["position"][active].copy() if tally.maze else None,
        ))  # fmt: skip
        tally.done[active[ended]] = True
    envs.close()
    out = _collect(tally, first_obs, steps)
    out.budget_cut = cut if max_total_steps is not None else None
    return out


def _episodes(
    env_id: str, episodes: int | None, split: str, env_kwargs: dict[str, Any] | None,
    layouts: np.ndarray | None,
) -> tuple[int, dict[str, Any], dict[str, Any]]:  # fmt: skip
    """How many episodes, the env's arguments and the reset options of a rollout."""
    kwargs = dict(env_kwargs or {})
    if env_kind(env_id) != "maze":
        return (100 if episodes is None else int(episodes)), kwargs, {}
    n = abco_envs.maze_size(env_id)
    given = layouts is not None
    available = len(layouts) if given else len(abco_envs.layout_pool(n).split(split))
    num = available if episodes is None else min(int(episodes), available)
    kwargs["split"] = "train" if given else split
    options: dict[str, Any] = ({"layout": np.asarray(layouts)[:num]} if given
                               else {"layout_index": list(range(num))})  # fmt: skip
    options["start"] = np.zeros((num, 2), dtype=int)
    return num, kwargs, options


@dataclass
class _Tally:
    """The running returns, lengths, successes and (mazes) cell visits of a batch of episodes."""

    env_name: str
    returns: np.ndarray
    lengths: np.ndarray
    successes: np.ndarray
    done: np.ndarray
    maze: bool
    paper: bool
    n: int = 0
    visits: np.ndarray | None = None
    layout_indices: np.ndarray | None = None
    layout_ids: list[str] | None = None
    first_pos: np.ndarray | None = None

    @classmethod
    def start(cls, env_id: str, num: int, info: dict[str, Any], paper: bool) -> _Tally:
        """The tally after the reset that returned ``info``."""
        maze = env_kind(env_id) == "maze"
        tally = cls(abco_envs.env_name(env_id), np.zeros(num), np.zeros(num, dtype=np.int64),
                    np.zeros(num, dtype=bool), np.zeros(num, dtype=bool), maze,
                    maze and paper)  # fmt: skip
        if maze:
            tally.n = n = abco_envs.maze_size(env_id)
            tally.visits = np.zeros((num, n * n), dtype=np.int64)
            cells = info["position"][:, 0] * n + info["position"][:, 1]
            tally.visits[np.arange(num), cells] = 1
            tally.layout_indices = np.asarray(info["layout_index"]).copy()
            tally.layout_ids = [str(x) for x in info["layout_id"]]
            tally.first_pos = info["position"].copy()
        return tally

    def step(self, active: np.ndarray, rewards: np.ndarray, terminated: np.ndarray,
             truncated: np.ndarray, info: dict[str, Any], max_steps: int | None
             ) -> np.ndarray:  # fmt: skip
        """Count one step of the ``active`` episodes; which of them ended."""
        self.returns[active] += rewards[active]
        self.lengths[active] += 1
        ended = (terminated | truncated)[active]
        if self.maze and self.paper and self.visits is not None:
            pos = info["position"][active]
            cells = pos[:, 0] * self.n + pos[:, 1]
            self.visits[active, cells] += 1
            looped = (self.visits[active, cells] >= PAPER_MAX_VISITS) & ~terminated[active]
            self.returns[active[looped]] = PAPER_FAIL_RETURN
            ended |= looped
        if max_steps is not None:
            ended |= self.lengths[active] >= max_steps
        # The env's rule (abco_envs.success), after every step: a return rule (LunarLander)
        # reads the return once the episode has ended, so `ended` must be final here.
        reported = {k: np.asarray(info[k])[active] for k in ("is_success", "_is_success")
                    if k in info}  # fmt: skip
        self.successes[active] = abco_envs.success_mask(
            self.env_name, terminated=terminated[active], lengths=self.lengths[active],
            returns=self.returns[active], ended=ended, info=reported)
        return ended


def _collect(tally: _Tally, first_obs: np.ndarray | None,
             steps: list[tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray | None]]
             ) -> Rollouts:  # fmt: skip
    """The :class:`Rollouts` of a finished batch: per-run paths and, when recorded, the
    observations and actions in run order."""
    num, lengths = len(tally.returns), tally.lengths
    out = Rollouts(tally.returns, tally.successes, lengths, tally.layout_indices,
                   tally.layout_ids)  # fmt: skip
    if tally.maze:
        out.paths = _per_run(num, tally.first_pos, [(a, _recorded(p)) for a, _, _, p in steps])
    if first_obs is not None:
        run_obs = _per_run(num, first_obs, [(a, _recorded(o)) for a, o, _, _ in steps])
        run_acts = _per_run(num, None, [(a, x) for a, _, x, _ in steps])
        starts = np.concatenate([[0], np.cumsum(lengths + 1)[:-1]])
        out.observations = np.concatenate(run_obs)
        out.actions = np.concatenate(run_acts).astype(np.int64)
        out.run_ids = np.repeat(np.arange(num), lengths)
        out.obs_t = np.concatenate([s + np.arange(t) for s, t in zip(starts, lengths)])
    return out


def _rows(info: dict[str, Any], active: np.ndarray, num: int) -> dict[str, Any]:
    """The ``active`` episodes' entries of a vector env's ``info`` (per-episode arrays only)."""
    return {k: v[active] for k, v in info.items()
            if isinstance(v, np.ndarray) and v.shape[:1] == (num,)}  # fmt: skip


def _recorded(rows: np.ndarray | None) -> np.ndarray:
    """A step's recorded rows: positions (mazes) and observations (``record``) are kept at
    every step of a rollout that keeps them at all."""
    assert rows is not None, "a step of a recorded rollout without its rows"
    return rows


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


def _references(rollouts: Rollouts, reference: Any) -> tuple[Any, Any]:
    """The expert and random reference returns of each episode (mazes: of its layout)."""
    if rollouts.layout_ids is not None and reference.layout_ids is not None:
        where = {lid: i for i, lid in enumerate(reference.layout_ids)}
        missing = [lid for lid in rollouts.layout_ids if lid not in where]
        if missing:
            raise KeyError(f"no reference returns for layouts {missing[:3]}...")
        idx = np.array([where[lid] for lid in rollouts.layout_ids])
        return (np.asarray(reference.expert_per_layout)[idx],
                np.asarray(reference.random_per_layout)[idx])  # fmt: skip
    return reference.expert_mean, reference.random_mean


def score(rollouts: Rollouts, reference: Any, per_episode: bool = False,
          score_reference: Any = None) -> dict[str, Any]:  # fmt: skip
    """AER, ``P`` (per episode against its own references, then averaged), success rate and,
    with ``score_reference``, the normalised score.

    Args:
        rollouts: The episodes.
        reference: The paper's ``P`` references, a :class:`abco_data.ReferenceReturns` (per
            layout for mazes).
        per_episode: Also list every episode's return and ``P`` (``episode_returns``,
            ``episode_performance``, and ``episode_scores`` with ``score_reference``), for
            confidence intervals over episodes.
        score_reference: References measured under the evaluation's own protocol
            (:mod:`abco_train.harness.score_reference`): adds ``score``, the mean over
            episodes of ``(R - random) / (expert - random)`` (``None`` where the two
            references coincide, e.g. a step cap no expert finishes within).
    """
    expert, random = _references(rollouts, reference)
    out: dict[str, Any] = summarize(rollouts.returns, rollouts.successes, expert, random)
    out["mean_length"] = float(rollouts.lengths.mean())
    scores = None
    if score_reference is not None:
        try:
            scores = performance(rollouts.returns, *_references(rollouts, score_reference))
            out["score"] = float(scores.mean())
        except ValueError:  # the expert does no better than random under this protocol
            out["score"] = None
    if per_episode:
        out["episode_returns"] = np.asarray(rollouts.returns, dtype=np.float64).tolist()
        out["episode_performance"] = performance(rollouts.returns, expert, random).tolist()
        if scores is not None:
            out["episode_scores"] = scores.tolist()
    return out
