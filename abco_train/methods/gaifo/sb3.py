"""GAIfO's stable-baselines3 pieces: the learner's env, its normaliser, its schedules, its PPO.

This module imports stable-baselines3 (the optional extra ``abco[rl]``) at its top;
:mod:`abco_train.methods.gaifo.method` imports it only when a GAIfO run starts, so that the
method is registered (and says what to install) without it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper, VecNormalize
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs
from torch import nn

from abco_train.methods.gaifo.options import GAIfOOptions
from abco_train.networks.encoders import conv_stack

__all__ = ["DiscriminatorReward", "SmallCNN", "RunProgress", "RunSchedule", "learner_env",
           "normalizer", "make_ppo", "normalizer_state", "load_normalizer_state"]  # fmt: skip


class DiscriminatorReward(VecEnvWrapper):
    """A VecEnv whose reward is ``reward_fn(s, s')``, batched over its envs; it keeps every
    pair it produced (the learner's transitions) until :meth:`take_pairs`."""

    def __init__(self, venv: Any, reward_fn: Callable[[np.ndarray, np.ndarray], np.ndarray]
                 ) -> None:  # fmt: skip
        super().__init__(venv)
        self.reward_fn = reward_fn
        self.last_obs: np.ndarray | None = None
        self._s: list[np.ndarray] = []
        self._s1: list[np.ndarray] = []
        self.rewards: list[np.ndarray] = []

    def reset(self) -> VecEnvObs:
        obs = self.venv.reset()
        self.last_obs = np.array(obs, copy=True)
        return obs

    def step_wait(self) -> Any:
        obs, _env_reward, dones, infos = self.venv.step_wait()  # the env's reward: dropped
        assert self.last_obs is not None, "reset() before step()"
        nxt = np.array(obs, copy=True)
        for i in np.flatnonzero(dones):  # the episode's last s', not the next one's first
            nxt[i] = infos[i]["terminal_observation"]
        rewards = np.asarray(self.reward_fn(self.last_obs, nxt), dtype=np.float32)
        self._s.append(self.last_obs)
        self._s1.append(nxt)
        self.rewards.append(rewards)
        self.last_obs = np.array(obs, copy=True)
        return obs, rewards, dones, infos

    def take_pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pairs (and their rewards) since the last call, in step order; forgets them."""
        out = (np.concatenate(self._s), np.concatenate(self._s1),
               np.concatenate(self.rewards))  # fmt: skip
        self._s, self._s1, self.rewards = [], [], []
        return out


class SmallCNN(BaseFeaturesExtractor):
    """The compact CNN's convolutions (:func:`abco_train.networks.encoders.conv_stack`, ReLU,
    no attention) for 64x64 frames (channels first, scaled to [0, 1] by SB3), then
    ``FC features_dim``: SB3's feature extractor for the PPO learner."""

    def __init__(self, observation_space: gym.spaces.Box, features_dim: int = 256) -> None:
        super().__init__(observation_space, features_dim)
        c, h, w = observation_space.shape
        self.body = conv_stack(c, nn.ReLU, attention=None)  # the compact CNN's convolutions
        with torch.no_grad():
            n = int(self.body(torch.zeros(1, c, h, w)).shape[1])
        self.head = nn.Sequential(nn.Linear(n, features_dim), nn.ReLU())

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.body(obs))


def _make_env(env_id: str, kwargs: dict[str, Any]) -> gym.Env:
    return Monitor(gym.make(env_id, **kwargs))


def learner_env(env_id: str, kwargs: dict[str, Any], n_envs: int,
                reward_fn: Callable[[np.ndarray, np.ndarray], np.ndarray]
                ) -> DiscriminatorReward:  # fmt: skip
    """``n_envs`` copies of the env (each in a Monitor, for the true return) whose reward is
    ``reward_fn(s, s')``."""
    venv = DummyVecEnv([functools.partial(_make_env, env_id, kwargs) for _ in range(n_envs)])
    return DiscriminatorReward(venv, reward_fn)


def normalizer(env: DiscriminatorReward, options: GAIfOOptions, *, frames: bool
               ) -> VecNormalize | None:  # fmt: skip
    """SB3's ``VecNormalize`` over ``env`` when ``options.normalize`` (the Zoo's
    ``normalize: true``), else ``None``: it standardises vector observations by their running
    mean and std (frames keep SB3's own scaling to [0, 1]) and scales the learner's rewards by
    the running std of their discounted return (``gamma`` = PPO's, as the Zoo sets it). It sits
    outside the discriminator's reward, which sees raw observations."""
    if not options.normalize:
        return None
    return VecNormalize(env, norm_obs=not frames, norm_reward=True, gamma=options.gamma)


@dataclass
class RunProgress:
    """How much of the run's planned PPO steps is still to come after the current rollout:
    1 before the first, 0 after the last. GAIfO sets it before every rollout."""

    remaining: float = 1.0


class RunSchedule:
    """A PPO schedule over the whole run's PPO steps: ``start`` (``constant``), or ``start``
    times the run's :class:`RunProgress` (``linear``, the Zoo's ``lin_`` schedules). SB3's own
    progress is that of one ``learn()`` call, and GAIfO calls it once per rollout.

    Example:
        >>> progress = RunProgress()
        >>> rate = RunSchedule(1e-3, "linear", progress)
        >>> progress.remaining = 0.25
        >>> rate(1.0), RunSchedule(0.2, "constant", progress)(1.0)
        (0.00025, 0.2)
    """

    def __init__(self, start: float, form: str, progress: RunProgress) -> None:
        if form not in ("constant", "linear"):
            raise ValueError(f"unknown schedule {form!r}; expected constant or linear")
        self.start, self.form, self.progress = float(start), form, progress

    def __call__(self, _learn_call_progress: float) -> float:
        if self.form == "linear":
            return self.start * self.progress.remaining
        return self.start

    def __repr__(self) -> str:
        return f"RunSchedule({self.start}, {self.form!r})"


def make_ppo(env: VecEnv, options: GAIfOOptions, *, frames: bool, progress: RunProgress,
             seed: int, device: torch.device) -> PPO:  # fmt: skip
    """PPO on ``env`` with ``options``' settings: a CNN policy (:class:`SmallCNN`, shared by
    the policy and the value) on frames, SB3's MLP policy on vectors; its learning rate and
    clip range follow ``progress`` (:class:`RunSchedule`); it logs nowhere."""
    opt = options
    policy_kwargs: dict[str, Any] = {"net_arch": list(opt.net_arch)}
    if frames:
        policy = "CnnPolicy"
        policy_kwargs.update(features_extractor_class=SmallCNN,
                             features_extractor_kwargs={"features_dim": opt.features_dim},
                             share_features_extractor=True)  # fmt: skip
    else:
        policy = "MlpPolicy"
    model = PPO(
        policy, env, n_steps=opt.n_steps, batch_size=opt.batch_size, n_epochs=opt.n_epochs,
        learning_rate=RunSchedule(opt.learning_rate, opt.learning_rate_schedule, progress),
        clip_range=RunSchedule(opt.clip_range, opt.clip_range_schedule, progress),
        gamma=opt.gamma, gae_lambda=opt.gae_lambda, ent_coef=opt.ent_coef,
        vf_coef=opt.vf_coef, max_grad_norm=opt.max_grad_norm, policy_kwargs=policy_kwargs,
        verbose=0, seed=seed, device=device,
    )  # fmt: skip
    # A logger of our own: without one, every learn() call makes a folder SB3-<date> in the
    # temp dir (SB3's default logger), thousands per grid.
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def normalizer_state(norm: VecNormalize) -> dict[str, Any]:
    """``norm``'s running statistics, as data (a checkpoint's): the observations' (when it
    normalises them) and the discounted returns'. Its per-env running returns are not kept:
    every iteration's first rollout resets the env, which zeroes them."""
    stats = {"return": norm.ret_rms}
    if norm.norm_obs:
        stats["obs"] = norm.obs_rms  # type: ignore[assignment]
    return {f"{name}_{part}": (float(rms.count) if part == "count"
                               else np.array(getattr(rms, part), dtype=np.float64))
            for name, rms in stats.items() for part in ("mean", "var", "count")}  # fmt: skip


def load_normalizer_state(norm: VecNormalize, state: dict[str, Any]) -> None:
    """Put :func:`normalizer_state`'s statistics back into ``norm``.

    Raises:
        KeyError: A statistic is missing.
        ValueError: One of another shape, not finite, a negative variance or a count <= 0.
    """
    stats = {"return": norm.ret_rms}
    if norm.norm_obs:
        stats["obs"] = norm.obs_rms  # type: ignore[assignment]
    for name, rms in stats.items():
        mean = np.asarray(state[f"{name}_mean"], dtype=np.float64)
        var = np.asarray(state[f"{name}_var"], dtype=np.float64)
        count = float(state[f"{name}_count"])
        if mean.shape != rms.mean.shape or var.shape != rms.var.shape:
            raise ValueError(f"normaliser's {name} statistics of shape {mean.shape}, "
                             f"expected {rms.mean.shape}")  # fmt: skip
        if not (np.isfinite(mean).all() and np.isfinite(var).all() and np.isfinite(count)
                and (var >= 0).all() and count > 0):  # fmt: skip
            raise ValueError(f"normaliser's {name} statistics are not finite means, "
                             "variances >= 0 and a count > 0")  # fmt: skip
        rms.mean, rms.var, rms.count = mean.copy(), var.copy(), count
