"""Record one episode of any policy in any Gymnasium env, as flat arrays.

A policy is any callable ``policy(obs, info) -> action``. The record keeps all ``T + 1``
observations (the final one included) and, for mazes, every agent position, so each frame can
be re-rendered and checked.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["Policy", "EpisodeRecord", "record_episode"]

Policy = Callable[[Any, dict[str, Any]], int]


@dataclass(frozen=True)
class EpisodeRecord:
    """One recorded episode.

    Attributes:
        observations: ``T + 1`` observations, the reset one first and the final one last.
        actions: ``T`` actions.
        rewards: ``T`` rewards.
        terminations: ``T`` flags; only the last can be set.
        truncations: ``T`` flags; only the last can be set.
        positions: ``(T + 1, 2)`` agent cells for mazes, else ``None``.
        layout: The maze layout played, else ``None``.
        seed: The reset seed.
    """

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    positions: np.ndarray | None
    layout: np.ndarray | None
    seed: int | None

    @property
    def length(self) -> int:
        """Number of transitions ``T``."""
        return len(self.actions)

    @property
    def episode_return(self) -> float:
        """Sum of the rewards."""
        return float(self.rewards.sum())


def record_episode(
    env: gym.Env[Any, Any],
    policy: Policy,
    seed: int | None = None,
    options: dict[str, Any] | None = None,
    max_steps: int | None = None,
) -> EpisodeRecord:
    """Run ``policy`` from ``env.reset(seed=seed, options=options)`` until the episode ends.

    Args:
        env: A Gymnasium env (with its time limit, as ``gym.make`` builds it).
        policy: ``policy(obs, info) -> action``. If it has a ``reset(env)`` method, that is
            called right after the env's reset (the maze expert reads the layout drawn).
        seed: Reset seed.
        options: Reset options.
        max_steps: Stop (as truncation) after this many steps even if the env would go on.

    Example:
        >>> import gymnasium as gym
        >>> from abco_envs.experts.random_policy import RandomPolicy
        >>> env = gym.make("CartPole-v1")
        >>> ep = record_episode(env, RandomPolicy(env.action_space, seed=0), seed=0)
        >>> len(ep.observations) == ep.length + 1
        True
    """
    obs, info = env.reset(seed=seed, options=options)
    if hasattr(policy, "reset"):
        policy.reset(env)
    observations, actions, rewards, terms, truncs = [obs], [], [], [], []
    positions = [info["position"]] if "position" in info else None
    done = False
    while not done:
        action = policy(obs, info)
        obs, reward, terminated, truncated, info = env.step(action)
        if max_steps is not None and len(actions) + 1 >= max_steps:
            truncated = truncated or not terminated
        observations.append(obs)
        actions.append(action)
        rewards.append(float(reward))
        terms.append(bool(terminated))
        truncs.append(bool(truncated))
        if positions is not None:
            positions.append(info["position"])
        done = terminated or truncated
    cells = getattr(env.unwrapped, "cells", None)
    return EpisodeRecord(
        observations=np.stack(observations),
        actions=np.asarray(actions, dtype=np.int64),
        rewards=np.asarray(rewards, dtype=np.float64),
        terminations=np.asarray(terms, dtype=bool),
        truncations=np.asarray(truncs, dtype=bool),
        positions=None if positions is None else np.stack(positions).astype(np.int64),
        layout=None if cells is None else np.array(cells),
        seed=seed,
    )
