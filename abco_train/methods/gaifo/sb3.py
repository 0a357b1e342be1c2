"""GAIfO's stable-baselines3 pieces: the learner's env, its feature extractors, its PPO.

This module imports stable-baselines3 (the optional extra ``abco[rl]``) at its top;
:mod:`abco_train.methods.gaifo.method` imports it only when a GAIfO run starts, so that the
method is registered (and says what to install) without it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs
from torch import nn

from abco_train.methods.gaifo.options import GAIfOOptions
from abco_train.networks.encoders import conv_stack
from abco_train.networks.layers import standardise

__all__ = ["DiscriminatorReward", "Standardize", "SmallCNN", "learner_env", "make_ppo"]


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


class Standardize(BaseFeaturesExtractor):
    """Vector observations standardised by fixed (expert) statistics, clipped to +-10."""

    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, observation_space: gym.spaces.Box, mean: list[float],
                 std: list[float]) -> None:  # fmt: skip
        super().__init__(observation_space, int(np.prod(observation_space.shape)))
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return standardise(obs.flatten(1), self.mean, self.std).clamp(-10.0, 10.0)


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


def make_ppo(env: DiscriminatorReward, options: GAIfOOptions, *, frames: bool,
             expert_states: np.ndarray, seed: int, device: torch.device) -> PPO:  # fmt: skip
    """PPO on ``env``: a CNN policy (:class:`SmallCNN`, shared by the policy and the value)
    on frames, an MLP on vectors standardised by the expert's ``expert_states``
    (:class:`Standardize`); it logs nowhere."""
    opt = options
    policy_kwargs: dict[str, Any] = {"net_arch": list(opt.net_arch)}
    if frames:
        policy = "CnnPolicy"
        policy_kwargs.update(features_extractor_class=SmallCNN,
                             features_extractor_kwargs={"features_dim": opt.features_dim},
                             share_features_extractor=True)  # fmt: skip
    else:
        policy = "MlpPolicy"
        s = expert_states.astype(np.float64)
        policy_kwargs.update(features_extractor_class=Standardize,
                             features_extractor_kwargs={
                                 "mean": s.mean(0).tolist(),
                                 "std": np.maximum(s.std(0), 1e-6).tolist()})  # fmt: skip
    model = PPO(
        policy, env, learning_rate=opt.learning_rate, n_steps=opt.n_steps,
        batch_size=opt.batch_size, n_epochs=opt.n_epochs, gamma=opt.gamma,
        gae_lambda=opt.gae_lambda, clip_range=opt.clip_range, ent_coef=opt.ent_coef,
        vf_coef=opt.vf_coef, max_grad_norm=opt.max_grad_norm, policy_kwargs=policy_kwargs,
        verbose=0, seed=seed, device=device,
    )  # fmt: skip
    # A logger of our own: without one, every learn() call makes a folder SB3-<date> in the
    # temp dir (SB3's default logger), thousands per grid.
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model
