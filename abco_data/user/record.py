"""Recording a dataset of the user's own from any Gymnasium env: :func:`record`.

A policy (:mod:`abco_data.user.policies`: a callable on one observation, a ``MODULE:CALLABLE``,
a Stable-Baselines3 model) plays the env; its episodes are written in abco's format by the
writer of the built-in datasets (:mod:`abco_data.user.writer`), every episode's ``T + 1``
observations, the actions kept as ``idm_eval_actions`` for an expert dataset and as
``actions`` for pre-demonstrations. Episode ``i`` is reset with seed ``seed + i`` (and a
random policy seeded with it), so the same policy, env and seed give the same file.

Reference returns, for Performance ``P`` and the normalised score: uniform random actions
over ``reference_episodes`` episodes reset with seeds ``12345 + i``, and the recorded policy
(the expert) over ``reference_expert_episodes`` episodes reset with seeds ``22345 + i``, as
for the built-in classic-control datasets; these seeds are apart from the recorded ones.

Example:
    >>> import tempfile, os, abco_data
    >>> path = record("CartPole-v1", lambda obs: int(obs[2] > 0), kind="expert", episodes=2,
    ...               seed=0, out=os.path.join(tempfile.mkdtemp(), "pole-doc.hdf5"),
    ...               reference_episodes=2, reference_expert_episodes=1, progress=False)
    >>> ds = abco_data.check_dataset(path, kind="expert", env_id="CartPole-v1")
    >>> ds.id, ds.num_episodes, ds.reference.expert_mean > ds.reference.random_mean
    ('local/pole-doc-v0', 2, True)
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

import abco_envs
from abco_data.errors import InvalidParameterError
from abco_data.format import to_json
from abco_data.format.files import check_target
from abco_data.generation.bounds import MAX_FRAME_BYTES, MAX_TRANSITIONS, check_params
from abco_data.generation.reference import REFERENCE_SEED, ReferenceReturns
from abco_data.progress import progress_bar
from abco_data.user.datasets import register_user_dataset, user_target
from abco_data.user.policies import Policy, checked_policy, load_policy, policy_name
from abco_data.user.writer import (
    EpisodeColumns,
    check_spaces,
    clean_observations,
    env_spec_json,
    kind_name,
    mean_return,
    write_episodes,
)

__all__ = ["record", "GENERATOR", "GENERATOR_VERSION"]

#: ``generator`` and ``generator_version`` of a recorded file.
GENERATOR = "abco_data.record"
GENERATOR_VERSION = 1
_EXPERT_SEED = REFERENCE_SEED + 10_000


def _make_env(env_id: str, env_kwargs: Mapping[str, Any]) -> Any:
    import gymnasium as gym

    try:
        return gym.make(env_id, **env_kwargs)
    except (gym.error.Error, ImportError, TypeError, ValueError, KeyError,
            AttributeError) as err:
        raise InvalidParameterError(f"cannot make env {env_id!r}: {type(err).__name__}:"
                                    f" {str(err).strip().splitlines()[0] if str(err) else ''}"
                                    ) from err


def _make_kwargs(env_id: str, env_kwargs: Mapping[str, Any] | None,
                 max_episode_steps: int | None) -> dict[str, Any]:
    """The keyword arguments of ``gymnasium.make`` (JSON, stored in the file), checked."""
    if abco_envs.is_maze(env_id):
        raise InvalidParameterError(f"{env_id}: the abco mazes have datasets of their own, with"
                                    " layouts and per-layout references: abco data generate"
                                    " ID --out FILE --set KEY=VALUE")
    kwargs = dict(env_kwargs or {})
    if max_episode_steps is not None:
        if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int) \
                or not 1 <= max_episode_steps <= MAX_TRANSITIONS:
            raise InvalidParameterError(f"max_episode_steps must be an integer from 1 to"
                                        f" {MAX_TRANSITIONS:,}, got {max_episode_steps!r}")
        kwargs["max_episode_steps"] = max_episode_steps
    try:
        to_json(kwargs)
    except (TypeError, ValueError) as err:
        raise InvalidParameterError(f"env_kwargs must be plain JSON data: {err}") from err
    return kwargs


def _check_work(dataset_id: str, env: Any, counts: Mapping[str, int]) -> None:
    """Bound the work before any: steps of every episode, and the observations' bytes."""
    limit = env.spec.max_episode_steps if env.spec is not None else None
    if limit is None:
        raise InvalidParameterError(f"{dataset_id}: {env.spec.id if env.spec else env} has no"
                                    " step limit; give one (max_episode_steps,"
                                    " --max-episode-steps N)")
    episodes = counts.get("episodes")
    steps = episodes * limit if episodes is not None else counts["transitions"]
    ref_steps = (counts["reference_episodes"] + counts["reference_expert_episodes"]) * limit
    for what, n in (("recorded episodes", steps), ("reference episodes", ref_steps)):
        if n > MAX_TRANSITIONS:
            raise InvalidParameterError(f"{dataset_id}: the {what} may take {n:,} steps"
                                        f" ({limit}-step episodes), more than the"
                                        f" {MAX_TRANSITIONS:,} a dataset may; ask fewer")
    rows = steps + (episodes if episodes is not None else steps)
    row_bytes = int(np.prod(env.observation_space.shape)) * env.observation_space.dtype.itemsize
    if rows * row_bytes > MAX_FRAME_BYTES:
        raise InvalidParameterError(f"{dataset_id}: up to {rows:,} observations of"
                                    f" {row_bytes:,} bytes, more than the"
                                    f" {MAX_FRAME_BYTES >> 30} GiB a dataset may hold")


def _episodes(env: Any, make_policy: Callable[[int], Policy], counts: Mapping[str, int],
              seed: int, where: str) -> Iterator[EpisodeColumns]:
    """Episode ``i`` from seed ``seed + i``, until the episodes or transitions asked for;
    the last episode is cut (truncated) to give the transitions exactly."""
    from abco_envs.experts import record_episode

    episodes, left, i = counts.get("episodes"), counts.get("transitions"), 0
    while (left is None and episodes is not None and i < episodes) or (left or 0) > 0:
        policy = make_policy(seed + i)
        ep = record_episode(env, lambda obs, info, p=policy: p(obs), seed=seed + i,
                            max_steps=left)
        obs = clean_observations(ep.observations, env.observation_space, f"{where} episode {i}")
        yield EpisodeColumns(obs, ep.actions, ep.rewards, ep.terminations, ep.truncations,
                             seed + i)
        left = None if left is None else left - ep.length
        i += 1


def _policies(env: Any, policy: Policy | str | None, kind: str, sb3_algo: str | None
              ) -> tuple[Callable[[int], Policy], Callable[[int], Policy], str]:  # fmt: skip
    """``(recorded policy by seed, uniform random policy by seed, the recorded one's name)``."""
    from abco_envs.experts import RandomPolicy

    def uniform(seed: int) -> Policy:
        drawn = RandomPolicy(env.action_space, seed=seed)
        return lambda obs: drawn(obs, {})

    if policy is None:
        if kind == "expert":
            raise InvalidParameterError("an expert dataset needs the expert's policy"
                                        " (policy, --policy MODULE:CALLABLE or MODEL.zip)")
        return uniform, uniform, "abco_envs.experts:RandomPolicy"
    name = policy if isinstance(policy, str) else policy_name(policy)
    loaded = load_policy(policy, sb3_algo=sb3_algo) if isinstance(policy, str) else policy
    played = checked_policy(loaded, env.action_space, name)
    return (lambda seed: played), uniform, name


def _references(env: Any, recorded: Callable[[int], Policy], uniform: Callable[[int], Policy],
                counts: Mapping[str, int], desc: str, progress: bool) -> ReferenceReturns:
    total = counts["reference_episodes"] + counts["reference_expert_episodes"]
    with progress_bar(total=total, unit="episodes", disable=not progress, leave=False,
                      desc=f"{desc} references") as bar:
        random = mean_return(uniform, env, counts["reference_episodes"], REFERENCE_SEED,
                             lambda: bar.update(1))
        expert = mean_return(recorded, env, counts["reference_expert_episodes"],
                             _EXPERT_SEED, lambda: bar.update(1))
    return ReferenceReturns(expert_mean=expert, random_mean=random)


def record(env_id: str, policy: Policy | str | None = None, *, kind: str = "expert",
           episodes: int | None = None, transitions: int | None = None, seed: int = 0,
           out: str | os.PathLike[str] | None = None, id: str | None = None,
           env_kwargs: Mapping[str, Any] | None = None, max_episode_steps: int | None = None,
           reference_episodes: int = 100, reference_expert_episodes: int = 20,
           sb3_algo: str | None = None, overwrite: bool = False, progress: bool = True,
           home: str | os.PathLike[str] | None = None) -> Path:
    """Record ``policy`` on ``env_id`` as an abco dataset; return the file.

    Args:
        env_id: A Gymnasium id; ``module:Id-v0`` imports ``module`` first (which registers
            it). Observations: a ``Box`` vector or ``uint8`` ``H x W x C`` image; actions:
            ``Discrete`` (others are refused in one line that says how to wrap the env).
        policy: A callable on one observation returning one action, a ``MODULE:CALLABLE``
            or the path of a Stable-Baselines3 model ``.zip`` (:mod:`abco_data.user.policies`).
            Default for ``kind="pre"``: uniform random actions; an expert needs one.
        kind: ``"expert"`` (the actions kept as ``idm_eval_actions``) or ``"pre"``.
        episodes: Record this many whole episodes; or
        transitions: record this many transitions (the last episode cut, truncated).
        seed: Episode ``i`` is reset with ``seed + i``.
        out: The file to write; default, with ``id``, ``<data home>/<namespace>/<NAME-vN>.hdf5``.
        id: A user dataset id (``local/NAME-v0``), registered in the user manifest
            (:mod:`abco_data.user.datasets`) so that ``abco_data.load(id)`` finds and checks
            it. Without it the file holds ``local/<file stem>-v0`` and is not registered.
        env_kwargs: Keyword arguments of ``gymnasium.make`` (stored in the file).
        max_episode_steps: A step limit for the env (``gymnasium.make``'s); needed when the
            env has none.
        reference_episodes: Episodes of uniform random actions for the random reference.
        reference_expert_episodes: Episodes of the policy for the expert reference.
        sb3_algo: The algorithm of a Stable-Baselines3 model (default: read from the model).
        overwrite: Replace a registered user dataset of the same id.
        progress: Progress bars on stderr.
        home: The abco data home (default ``$ABCO_DATA_HOME``).

    Raises:
        InvalidParameterError: A bad argument, count, id, env, space or policy (one line).
        InvalidTargetError: ``out`` is a device, a FIFO, a folder or a symbolic link.
        DatasetError: The env gave data abco cannot store (observations outside its space).
        DatasetWriteError: Writing failed; the target was left as it was.
    """
    kind, make_kwargs = kind_name(kind), _make_kwargs(env_id, env_kwargs, max_episode_steps)
    if (episodes is None) == (transitions is None):
        raise InvalidParameterError("give either episodes or transitions (one of them)")
    path, dataset_id, register = user_target(out, id, overwrite=overwrite, home=home)
    check_target(path)
    counts = {k: v for k, v in (("episodes", episodes), ("transitions", transitions),
                                ("reference_episodes", reference_episodes),
                                ("reference_expert_episodes", reference_expert_episodes))
              if v is not None}
    # The totals are checked once the env's step limit is known (_check_work).
    check_params(dataset_id, env_id, "pre_demonstrations", {**counts, "seed": seed})
    env = _make_env(env_id, make_kwargs)
    try:
        check_spaces(env.observation_space, env.action_space, env_id)
        _check_work(dataset_id, env, counts)
        recorded, uniform, name = _policies(env, policy, kind, sb3_algo)
        attrs = {"dataset_id": dataset_id, "env_id": abco_envs.env_name(env_id),
                 "env_spec": env_spec_json(env.spec), "env_kwargs": to_json(make_kwargs),
                 "generator": GENERATOR, "generator_version": GENERATOR_VERSION, "seed": seed,
                 "creation_params": to_json({**counts, "seed": seed, "env": env_id,
                                             "policy": name, "env_kwargs": make_kwargs})}
        reference = _references(env, recorded, uniform, counts, dataset_id, progress)
        unit = "episodes" if episodes is not None else "transitions"
        with progress_bar(total=episodes or transitions, unit=unit, disable=not progress,
                          desc=dataset_id, leave=False) as bar:
            write_episodes(path, _episodes(env, recorded, counts, seed, dataset_id), kind=kind,
                           attrs=attrs, observation_space=env.observation_space,
                           action_space=env.action_space, reference=reference,
                           on_episode=lambda n: bar.update(1 if episodes is not None else n))
    finally:
        env.close()
    if register:
        register_user_dataset(dataset_id, path, env_id=attrs["env_id"], kind=kind, home=home)
    return path
