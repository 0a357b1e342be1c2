"""What the offline methods (:mod:`~abco_train.methods.dilo`, :mod:`~abco_train.methods.lapo`)
share: the run's data on its device, networks of the run's encoder family, their schedule.

Both learn from the datasets alone: the expert's states and the pre-demonstrations (whose
action labels they may read), with no rollout of their own. Their networks come from
:func:`~abco_train.networks.builders.build_networks`, the table every method of a task builds
from: a network reading one state is the run's policy network, one reading a transition
``(s, s')`` is the run's IDM network, each with the outputs the method needs. So on a task
every method sees the same observations through the same encoders (a maze's cell networks
included); only the cell planner, whose head plans over the maze's four moves, needs action
outputs, and a network with other outputs reads the maze through the same cell encoder
without it (:func:`state_network`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from abco_data.torch_view import frames_tensor
from abco_train.config.run import RunConfig
from abco_train.harness.training_data import TrainingData
from abco_train.methods.base import Method
from abco_train.networks.builders import build_networks, data_statistics
from abco_train.networks.heads import IDMNet

__all__ = ["OfflineMethod", "OfflineData", "offline_data", "state_network",
           "transition_network", "iteration_steps", "triples"]  # fmt: skip


class OfflineMethod(Method):
    """A method that learns from the datasets alone: its gradient steps are spread over
    ``rounds`` iterations (an option of its own, not the run's ``iterations``, which is the
    BCO family's alpha), each evaluated; a spent budget ends none of them."""

    online = False
    options: Any  # its options class has ``rounds`` (DILOOptions, LAPOOptions)

    @classmethod
    def defaults(cls, name: str) -> Mapping[str, Any]:
        """No self-attention by default: DILO's and LAPO's papers train plain networks, and
        the attention is ABCO's own (and IUPE's); the BCO family, ILPO and GAIfO go without
        it too (``--attention`` puts it back)."""
        return {"attention": False}

    @property
    def num_iterations(self) -> int:
        """The method's ``rounds``."""
        return int(self.options.rounds)


@dataclass
class OfflineData:
    """A run's datasets as tensors on its device (indices and actions on the CPU).

    Attributes:
        pre_obs: Pre-demonstration observations (frames drawn on the device).
        pre_t: Row of ``s_t`` of each pre-demonstration transition the run paid for.
        pre_actions: Their true actions.
        expert_obs: Expert observations.
        expert_t: Row of ``s_t`` of each expert transition.
        stats: The network statistics (:func:`~abco_train.networks.builders.data_statistics`).
    """

    pre_obs: Any
    pre_t: torch.Tensor
    pre_actions: torch.Tensor
    expert_obs: Any
    expert_t: torch.Tensor
    stats: dict[str, Any]

    def pre_pairs(self, idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(s, s')`` of pre-demonstration transitions ``idx``."""
        rows = self.pre_t[idx]
        return self.pre_obs[rows], self.pre_obs[rows + 1]

    def expert_pairs(self, idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(s, s')`` of expert transitions ``idx``."""
        rows = self.expert_t[idx]
        return self.expert_obs[rows], self.expert_obs[rows + 1]


def offline_data(method: Method, data: TrainingData, device: torch.device) -> OfflineData:
    """The run's data for an offline method, its pre-demonstrations counted.

    With a ``--budget`` the method trains on the first pre-demonstration transitions the
    budget pays for; every transition it trains on is counted as a ``pre_demonstration``
    interaction, once.
    """
    paid = method.budget_left  # None: all of them
    pre_t, pre_actions = data.pre_t[:paid], data.pre_actions[:paid]
    method.count("pre_demonstration", len(pre_t))
    stats = data_statistics(method.config.env, data.pre_obs, pre_t, len(pre_t) < len(data.pre_t))
    return OfflineData(
        pre_obs=frames_tensor(data.pre_obs, device), pre_t=torch.from_numpy(pre_t),
        pre_actions=torch.from_numpy(pre_actions),
        expert_obs=frames_tensor(data.expert_obs, device),
        expert_t=torch.from_numpy(data.expert_t), stats=stats,
    )  # fmt: skip


def _arch(config: RunConfig) -> str:
    assert config.arch is not None, "the run's config is resolved before its method is built"
    return config.arch


def state_network(config: RunConfig, data: TrainingData, stats: dict[str, Any], outputs: int,
                  actions: bool = False) -> nn.Module:  # fmt: skip
    """The run's policy network (``s -> outputs``). ``actions``: its outputs are the env's
    actions (the cell planner's head may plan over them); else, on ``cellplan``, the same cell
    encoder without the planner (``cellnet``)."""
    arch = _arch(config)
    if arch == "cellplan" and not actions:
        arch = "cellnet"
    policy, _ = build_networks(data.observation_space, outputs, arch, bool(config.attention),
                               **stats)  # fmt: skip
    return policy


def transition_network(config: RunConfig, data: TrainingData, stats: dict[str, Any],
                       outputs: int) -> IDMNet:  # fmt: skip
    """The run's IDM network (``(s, s') -> outputs``)."""
    _, idm = build_networks(data.observation_space, outputs, _arch(config),
                            bool(config.attention), **stats)  # fmt: skip
    assert isinstance(idm, IDMNet), "every builder's IDM is an IDMNet"
    return idm


def iteration_steps(total: int, iteration: int, iterations: int) -> int:
    """Iteration ``iteration``'s share of ``total`` gradient steps spread evenly over
    ``iterations`` (the shares sum to ``total`` whatever the count).

    Example:
        >>> [iteration_steps(10, i, 3) for i in range(3)]
        [3, 3, 4]
    """
    return total * (iteration + 1) // iterations - total * iteration // iterations


def triples(obs_t: np.ndarray) -> np.ndarray:
    """The transitions ``t`` of ``obs_t`` whose next state starts a transition too, so that
    ``(s_t, s_t+1, s_t+2)`` lie in one episode.

    Example:
        >>> triples(np.array([0, 1, 2, 4, 5])).tolist()  # rows 3 and 6 end episodes
        [0, 1, 3]
    """
    return np.flatnonzero(np.isin(obs_t + 1, obs_t))
