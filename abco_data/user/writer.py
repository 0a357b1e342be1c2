"""Writing the user's own datasets in abco's format: what recording and Minari import share.

:func:`write_episodes` writes episodes through :class:`~abco_data.format.DatasetWriter`, the
writer of the built-in datasets, with the same columns and root attributes
(``docs/format.md``): every episode's ``T + 1`` observations, the actions of a
pre-demonstration set as ``actions``, an expert's as ``idm_eval_actions``, and the reference
returns as the two root means. :func:`check_spaces` says which spaces abco stores: ``Box``
observations (a vector, or a ``uint8`` ``H x W x C`` image) and ``Discrete`` actions from 0.

Example:
    >>> from gymnasium import spaces
    >>> check_spaces(spaces.Box(0, 1, (4,)), spaces.Discrete(2), "CartPole-v1")
    >>> check_spaces(spaces.Dict({"image": spaces.Box(0, 255, (7, 7, 3), "uint8")}),
    ...              spaces.Discrete(7), "MiniGrid-Empty-5x5-v0")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    abco_data.errors.InvalidParameterError: MiniGrid-Empty-5x5-v0: abco stores Box ...ImgObsWrapper...
"""  # noqa: E501

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from abco_data.errors import DatasetError, InvalidParameterError
from abco_data.format import (
    FORMAT_NAME,
    FORMAT_VERSION,
    DatasetWriter,
    action_column,
    space_to_json,
    to_json,
)
from abco_data.generation.reference import ReferenceReturns

__all__ = ["KIND_NAMES", "kind_name", "EpisodeColumns", "check_spaces", "clean_observations",
           "write_episodes", "env_spec_json", "mean_return", "SPACES_HINT"]

#: What to do with a space abco does not store (the end of :func:`check_spaces`' message).
SPACES_HINT = (
    "; wrap the env so that it gives one, e.g. gymnasium.wrappers.FlattenObservation for a"
    " Dict or Tuple of vectors, minigrid.wrappers.ImgObsWrapper for MiniGrid's image,"
    " gymnasium.wrappers.DiscretizeAction for a Box of actions (see 'Your own datasets' in"
    " docs/datasets.md)")


#: Accepted names of each dataset kind.
KIND_NAMES = {"expert": "expert", "pre": "pre_demonstrations",
              "pre_demonstrations": "pre_demonstrations"}


def kind_name(kind: object) -> str:
    """``"expert"`` or ``"pre_demonstrations"`` of one of :data:`KIND_NAMES`.

    Raises:
        InvalidParameterError: Another kind.
    """
    if not isinstance(kind, str) or kind not in KIND_NAMES:
        raise InvalidParameterError(f"unknown dataset kind {kind!r}; expected 'expert' or"
                                    " 'pre' (pre-demonstrations)")
    return KIND_NAMES[kind]


class EpisodeColumns(NamedTuple):
    """One episode to write: ``T + 1`` observations and ``T`` of everything else."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    seed: int


def _is_image(space: spaces.Box) -> bool:
    return len(space.shape) == 3 and space.dtype == np.uint8


def check_spaces(observation_space: Any, action_space: Any, what: str) -> None:
    """Refuse, in one line naming what is supported, spaces abco cannot store.

    Raises:
        InvalidParameterError: Observations other than a ``Box`` vector or ``uint8``
            ``H x W x C`` image, or actions other than ``Discrete`` from 0.
    """
    obs_ok = isinstance(observation_space, spaces.Box) and (
        len(observation_space.shape) == 1 or _is_image(observation_space))
    act_ok = isinstance(action_space, spaces.Discrete) and int(action_space.start) == 0
    if not (obs_ok and act_ok):
        raise InvalidParameterError(
            f"{what}: abco stores Box observations (a vector, or a uint8 HxWxC image) and"
            f" Discrete actions from 0; this env has observation space {observation_space}"
            f" and action space {action_space}{SPACES_HINT}")


def clean_observations(observations: Any, space: spaces.Box, where: str) -> np.ndarray:
    """``observations`` as an array of ``space``'s dtype, checked: shape, finite, inside.

    Raises:
        DatasetError: Another shape, a dtype that does not cast safely, a NaN or infinite
            value, or a value outside the space (the message says which and ``where``).
    """
    obs = np.asarray(observations)
    if obs.shape[1:] != space.shape:
        raise DatasetError(f"{where}: observations of shape {obs.shape[1:]}, not the"
                           f" observation space's {space.shape}")
    if obs.dtype != space.dtype:
        if not np.can_cast(obs.dtype, space.dtype, "same_kind"):
            raise DatasetError(f"{where}: observations of dtype {obs.dtype} do not fit the"
                               f" observation space's {space.dtype}")
        obs = obs.astype(space.dtype)
    if obs.dtype.kind == "f" and not np.isfinite(obs).all():
        raise DatasetError(f"{where}: observations hold NaN or infinite values")
    if obs.size and (np.any(obs.min(axis=0) < space.low) or np.any(obs.max(axis=0) > space.high)):
        raise DatasetError(f"{where}: observations outside the observation space {space}"
                           " (abco stores only observations inside it)")
    return obs


def env_spec_json(spec: Any) -> str:
    """JSON of a Gymnasium ``EnvSpec``; a callable in it (an entry point, a wrapper) is
    written as its qualified name, where ``EnvSpec.to_json`` refuses it."""
    try:
        return spec.to_json()
    except (ValueError, TypeError):
        fields = dataclasses.asdict(spec)
        for name in ("namespace", "name", "version"):
            fields.pop(name, None)
        return json.dumps(fields, sort_keys=True, default=lambda v: getattr(
            v, "__module__", "") + ":" + getattr(v, "__qualname__", repr(v)))


def mean_return(make_policy: Callable[[int], Callable[[Any], Any]], env: Any, episodes: int,
                seed: int, on_episode: Callable[[], object] = lambda: None) -> float:
    """Mean return of ``episodes`` episodes of ``env``, episode ``i`` reset with seed
    ``seed + i`` and played by ``make_policy(seed + i)`` (a policy on observations)."""
    total = 0.0
    for i in range(episodes):
        policy = make_policy(seed + i)
        obs, _ = env.reset(seed=seed + i)
        done = False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += float(reward)
            done = bool(terminated or truncated)
        on_episode()
    if not np.isfinite(total):
        raise DatasetError("the reference episodes' returns are not finite")
    return total / episodes


def _episode_rows(ep: EpisodeColumns, where: str) -> int:
    """Check one episode's shapes and end; its length ``T``."""
    n = len(ep.actions)
    if n < 1 or len(ep.observations) != n + 1 or not (
            len(ep.rewards) == len(ep.terminations) == len(ep.truncations) == n):
        raise DatasetError(f"{where}: an episode needs T >= 1 actions, rewards, terminations"
                           f" and truncations and T + 1 observations, got {n} actions and"
                           f" {len(ep.observations)} observations")
    ends = np.asarray(ep.terminations, bool) | np.asarray(ep.truncations, bool)
    if ends[:-1].any() or not ends[-1]:
        raise DatasetError(f"{where}: an episode must end (terminate or truncate) on its last"
                           " transition and only there")
    if not np.isfinite(np.asarray(ep.rewards, dtype=np.float64)).all():
        raise DatasetError(f"{where}: rewards hold NaN or infinite values")
    return n


def write_episodes(path: str | os.PathLike[str], episodes: Iterable[EpisodeColumns], *,
                   kind: str, attrs: Mapping[str, Any], observation_space: spaces.Box,
                   action_space: spaces.Discrete,
                   reference: ReferenceReturns | Callable[[np.ndarray], ReferenceReturns],
                   on_episode: Callable[[int], object] = lambda n: None) -> tuple[int, int]:
    """Write ``episodes`` as an abco dataset file at ``path`` (atomically).

    Args:
        path: The target file.
        episodes: The episodes, in file order.
        kind: ``"expert"`` (actions stored as ``idm_eval_actions``) or
            ``"pre_demonstrations"`` (as ``actions``).
        attrs: Root attributes of the caller (``dataset_id``, ``env_id``, ``env_spec``,
            ``env_kwargs``, ``generator``, ``generator_version``, ``seed``,
            ``creation_params``); the format's own, the counts, the spaces and the
            references are added here.
        observation_space: The observation space (checked by :func:`check_spaces`).
        action_space: The action space.
        reference: The reference returns (the two means), or a function that makes them of
            the episodes' returns.
        on_episode: Called with each episode's length once it is written (progress).

    Returns:
        ``(episodes, transitions)`` written.

    Raises:
        DatasetError: No episode, or an episode that breaks the format's rules.
        DatasetWriteError: Writing failed; ``path`` was left as it was.
    """
    actions_name = action_column(kind)
    seeds, lengths, returns = [], [], []
    with DatasetWriter(Path(path)) as w:
        for ep in episodes:
            n = _episode_rows(ep, f"{attrs['dataset_id']}, episode {len(lengths)}")
            w.append_steps(actions_name, ep.observations, ep.actions, ep.rewards,
                           ep.terminations, ep.truncations)  # fmt: skip
            seeds.append(int(ep.seed))
            lengths.append(n)
            returns.append(float(np.sum(np.asarray(ep.rewards, dtype=np.float64))))
            on_episode(n)
        if not lengths:
            raise DatasetError(f"{attrs['dataset_id']}: no episode to write")
        n_tr = w.append_episode_index(lengths, seeds, returns)
        if callable(reference):
            reference = reference(np.asarray(returns, dtype=np.float64))
        w.attrs.update({
            **attrs, "format": FORMAT_NAME, "format_version": FORMAT_VERSION, "kind": kind,
            "observation_space": space_to_json(observation_space),
            "action_space": space_to_json(action_space), "overrides": to_json([]),
            "num_episodes": len(lengths), "num_transitions": n_tr,
            "num_observations": n_tr + len(lengths),
            "reference_expert_mean": float(reference.expert_mean),
            "reference_random_mean": float(reference.random_mean),
        })
    return len(lengths), n_tr
