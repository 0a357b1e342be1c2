"""ILPO's action remapping (Sec. 3.3 of the paper): which real action each latent action is.

:func:`remapping_steps` takes the counted environment steps (epsilon-greedy with the current
mapping; mazes: the train split's layouts in turn) and :class:`ActionRemapping` keeps the steps
some latent explains and fits ``P(a | s, z*)`` on them, or counts ``P(a | z*)`` (``remap``
``table``). :mod:`abco_train.methods.ilpo.method` says where each part fits in ILPO.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

import abco_envs
from abco_train.config.run import RunConfig
from abco_train.harness.rollouts import make_vector_env
from abco_train.harness.training_data import TrainingData
from abco_train.methods.ilpo.networks import ILPONet, RemapNet, minibatches
from abco_train.methods.ilpo.options import ILPOOptions

__all__ = ["ActionRemapping", "remapping_steps"]


def remapping_steps(
    config: RunConfig,
    data: TrainingData,
    options: ILPOOptions,
    phase: int,
    rng: np.random.Generator,
    act: Callable[[np.ndarray], np.ndarray],
    epsilon: float,
    limit: int | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``remap_steps`` environment steps (rounded up to whole steps of all ``remap_envs``
    slots): with probability ``epsilon`` a uniformly random action, else ``act``'s.

    With ``limit`` (the run's budget left, at least 1) they are at most ``limit`` steps: at
    most ``limit`` slots, and the round stops before a step of its slots that would take it
    over (each slot's move is an interaction); below the limit nothing changes.

    The slots are a vector env of their own, reset with a seed drawn from ``rng``; on a maze
    round ``phase`` starts its slots on the next layouts of the train split (cycling), at the
    start cell, episodes cut after ``remap_max_steps``. The step after an episode ends is the
    env's reset, not a transition, and is left out.

    Returns:
        ``(s, s', a)`` of every transition taken (CPU tensors; the caller counts them).
    """
    slots = int(options.remap_envs) if limit is None else min(int(options.remap_envs), limit)
    kwargs, reset_options = dict(data.env_kwargs), None
    if data.is_maze:
        n = abco_envs.maze_size(config.env)
        layouts = len(abco_envs.layout_pool(n).split("train"))
        kwargs.update(split="train", max_episode_steps=int(options.remap_max_steps or 0))
        first = phase * slots
        reset_options = {"layout_index": [(first + i) % layouts for i in range(slots)],
                         "start": np.zeros((slots, 2), dtype=int)}  # fmt: skip
    envs = make_vector_env(config.env, slots, kwargs)
    obs, _ = envs.reset(seed=int(rng.integers(0, 2**31 - slots)), options=reset_options)
    resetting = np.zeros(slots, dtype=bool)  # next-step autoreset: that step is no move
    s_rows, s1_rows, a_rows, taken = [], [], [], 0
    for _ in range(math.ceil(int(options.remap_steps) / slots)):
        moved = ~resetting
        taken += int(moved.sum())
        if limit is not None and taken > limit:
            break
        explore = rng.random(slots) < epsilon
        random_actions = rng.integers(0, data.n_actions, slots)
        actions = random_actions if explore.all() else np.where(
            explore, random_actions, act(obs))  # fmt: skip
        next_obs, _, terminated, truncated, _ = envs.step(actions)
        s_rows.append(obs[moved])
        s1_rows.append(next_obs[moved])
        a_rows.append(actions[moved])
        resetting = terminated | truncated
        obs = next_obs
    envs.close()
    s, s1 = torch.from_numpy(np.concatenate(s_rows)), torch.from_numpy(np.concatenate(s1_rows))
    return s, s1, torch.from_numpy(np.concatenate(a_rows).astype(np.int64))


class ActionRemapping:
    """``P(a | s, z)`` and the remapping steps kept so far: ``(s, z*, a)`` of every step some
    latent explains.

    ``remap="state"``: a small classifier (:class:`RemapNet`, as the authors' remapping
    network) reads :meth:`inputs`; ``remap="table"``: the counts of ``(z*, a)``.

    Args:
        net: ILPO's networks (the remapping reads them, detached, and never trains them).
        n_actions: The env's number of actions.
        options: ILPO's options (``latents``, ``remap``, ``remap_input``).
        obs_shape: One observation's shape.
        obs_dtype: The observations' dtype.
        device: Where the networks live.
        lr: The classifier's Adam learning rate.
    """

    def __init__(self, net: ILPONet, n_actions: int, options: ILPOOptions,
                 obs_shape: tuple[int, ...], obs_dtype: torch.dtype, device: torch.device,
                 lr: float) -> None:  # fmt: skip
        self.net, self.k, self.mode = net, int(options.latents or 0), options.remap
        self.input_mode, self.device = options.remap_input, device
        forward_model: Any = net.forward_model  # its feature counts are ints
        in_features = self.k
        in_features += forward_model.embedding_features if "embedding" in self.input_mode else 0
        in_features += forward_model.out_features if "effect" in self.input_mode else 0
        self.remap_net = RemapNet(int(in_features), n_actions).to(device)
        self.remap_opt = torch.optim.Adam(self.remap_net.parameters(), lr=lr)
        self.obs = torch.zeros((0, *obs_shape), dtype=obs_dtype)
        self.z = torch.zeros(0, dtype=torch.long)
        self.actions = torch.zeros(0, dtype=torch.long)
        self.counts = np.zeros((self.k, n_actions), dtype=np.int64)
        #: Rounds of remapping steps taken so far.
        self.phases = 0

    @torch.no_grad()
    def inputs(self, obs: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """What the remapping classifier reads of ``(s, z)`` (ILPO's networks, detached).

        Always ``onehot(z)``; ``remap_input`` adds ``E(s)`` (``"embedding"``, the authors'
        remapping network), what latent ``z`` does in ``s``, ``G(E(s), z) - mean_z'
        G(E(s), z')`` (``"effect"``), or both (``"effect+embedding"``, the default). The effect
        lets a latent whose meaning changes from one region of the state space to another (the
        min-over-latents loss does not forbid it) be mapped by what it does there, from
        remapping steps taken elsewhere.
        """
        self.net.eval()
        h, pred, _ = self.net(obs)
        mode = self.input_mode
        parts = [F.one_hot(z, self.k).to(h.dtype)]
        if mode in ("embedding", "effect+embedding"):
            parts.append(h)
        if mode in ("effect", "effect+embedding"):
            rows = torch.arange(len(z), device=z.device)
            parts.append(pred[rows, z] - pred.mean(1))
        return torch.cat(parts, dim=1)

    @torch.no_grad()
    def action(self, obs: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """``argmax_a P(a | s, z)`` (``obs`` and ``z`` on the device)."""
        if self.mode == "table":
            table = torch.as_tensor(self.counts, device=z.device)
            return table[z].argmax(1)
        self.remap_net.eval()
        return self.remap_net(self.inputs(obs, z)).argmax(1)

    def keep(self, obs: torch.Tensor, z: torch.Tensor, actions: torch.Tensor) -> None:
        """Add remapping steps ``(s, z*, a)`` (CPU tensors) to the kept ones and the counts."""
        self.obs = torch.cat([self.obs, obs])
        self.z = torch.cat([self.z, z])
        self.actions = torch.cat([self.actions, actions])
        np.add.at(self.counts, (z.numpy(), actions.numpy()), 1)

    def fit(self, epochs: int, batch_size: int, rng: np.random.Generator) -> dict[str, float]:
        """Fit ``P(a | s, z)`` on every kept step so far for ``epochs`` epochs (cross-entropy;
        nothing with ``remap="table"``); the mean loss of the last (up to) 20 minibatches."""
        n = len(self.z)
        if self.mode == "table" or n == 0:
            return {}
        self.remap_net.train()
        losses = []
        steps = epochs * math.ceil(n / batch_size)
        for idx in minibatches(rng, n, steps, batch_size):
            inputs = self.inputs(self.obs[idx].to(self.device), self.z[idx].to(self.device))
            loss = F.cross_entropy(self.remap_net(inputs), self.actions[idx].to(self.device))
            self.remap_opt.zero_grad(set_to_none=True)
            loss.backward()
            self.remap_opt.step()
            losses = [*losses[-19:], loss.item()]
        return {"remap_loss": float(np.mean(losses)) if losses else float("nan")}

    def state_dict(self) -> dict[str, Any]:
        """The classifier, its optimiser, the kept steps, the counts and the rounds taken
        (keys ``remap_*``, as ILPO's checkpoints hold them)."""
        return {
            "remap_net": self.remap_net.state_dict(), "remap_opt": self.remap_opt.state_dict(),
            "remap_obs": self.obs, "remap_z": self.z, "remap_actions": self.actions,
            "remap_counts": self.counts, "remap_phases": self.phases,
        }  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict` (other keys of ``state`` are ignored).

        Raises:
            TypeError: Kept steps, counts or rounds that are not what it stores.
        """
        steps = [state[k] for k in ("remap_obs", "remap_z", "remap_actions")]
        counts = state["remap_counts"]
        if not (all(isinstance(x, torch.Tensor) for x in steps)
                and isinstance(counts, np.ndarray) and counts.shape == self.counts.shape
                and counts.dtype == self.counts.dtype and type(state["remap_phases"]) is int):
            raise TypeError("remapping steps, counts or rounds that are not ILPO's")
        self.remap_net.load_state_dict(state["remap_net"])
        self.remap_opt.load_state_dict(state["remap_opt"])
        self.obs, self.z = state["remap_obs"], state["remap_z"]
        self.actions, self.counts = state["remap_actions"], state["remap_counts"]
        self.phases = state["remap_phases"]
