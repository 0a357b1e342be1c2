"""Heads and the two roles every network plays.

* the *policy model* (PM, :class:`PolicyNet`) maps one state ``s_t`` to action logits;
* the *inverse dynamics model* (IDM, :class:`IDMNet`) maps a pair ``(s_t, s_t+1)`` to action
  logits.
"""

from __future__ import annotations

import torch
from torch import nn

from abco_train.config.run import IDM_INPUTS

__all__ = ["PolicyNet", "IDMNet", "action_head", "small_head", "IDM_INPUTS"]


def action_head(in_features: int, hidden: int | None, n_actions: int, dropout: float) -> nn.Module:
    """The action layer; with ``hidden`` the paper's ``FC -> LeakyReLU -> Dropout`` stack."""
    if hidden is None:
        return nn.Linear(in_features, n_actions)
    return nn.Sequential(
        nn.Linear(in_features, hidden), nn.LeakyReLU(), nn.Dropout(dropout),
        nn.Linear(hidden, 512), nn.LeakyReLU(), nn.Dropout(dropout),
        nn.Linear(512, n_actions),
    )  # fmt: skip


def small_head(in_features: int, n_actions: int) -> nn.Module:
    """``FC 128 -> LeakyReLU -> FC n_actions``: the compact CNN's and the cell networks' head."""
    return nn.Sequential(nn.Linear(in_features, 128), nn.LeakyReLU(),
                         nn.Linear(128, n_actions))  # fmt: skip


class PolicyNet(nn.Module):
    """Policy model: ``encoder(s_t) -> head -> logits``."""

    def __init__(self, encoder: nn.Module, head: nn.Module) -> None:
        super().__init__()
        self.encoder, self.head = encoder, head

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Action logits for a batch of observations."""
        return self.head(self.encoder(obs))


class IDMNet(nn.Module):
    """Inverse dynamics model: ``P(a | s_t, s_t+1)`` as logits.

    Two ways of reading a transition (:data:`IDM_INPUTS`):

    * ``difference``: one encoder reads ``concat(s_t, s_t+1 - s_t)`` (features for vector
      states, channels for frames). The same information as the pair, re-expressed so that
      what changed stands apart: MountainCar's small velocity change is standardised on its
      own scale, and a maze frame's difference is zero everywhere but the agent's old and new
      cell. The paper's 12-input vector IDM for 6-dim states is this form.
    * ``pair`` (frames only): one shared encoder encodes each frame, the head reads both
      feature vectors (the paper's image IDM). On small cells (2x2 pixels at 10x10) the move
      must survive the encoder's strides in each frame separately, and it can fail to: the
      IDM stays at chance.
    """

    def __init__(self, encoder: nn.Module, head: nn.Module, concat_inputs: bool) -> None:
        super().__init__()
        self.encoder, self.head, self.concat_inputs = encoder, head, concat_inputs

    def forward(self, obs: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
        """Action logits for a batch of transitions."""
        return self.from_input(self.pair_input(obs, next_obs))

    def pair_input(self, obs: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
        """What the network reads of a batch of transitions, built once for callers that
        read the same transitions through several copies of the network (DILO's online and
        target utilities): ``(s, s' - s)`` on the last dim (frames scaled to ``[0, 1]``
        first), or with ``pair`` both batches one after the other (:meth:`stacked_input`
        joins several)."""
        if not self.concat_inputs:
            return torch.cat([obs, next_obs], dim=0)
        if obs.dtype != torch.uint8:
            return torch.cat([obs, next_obs - obs], dim=-1)
        # frames: a signed difference needs floats; written into one buffer, not concatenated
        first = obs.float().div_(255.0)
        out = torch.empty(*first.shape[:-1], 2, first.shape[-1], dtype=first.dtype,
                          device=first.device)  # fmt: skip
        out[..., 0, :] = first
        torch.sub(next_obs.float().div_(255.0), first, out=out[..., 1, :])
        return out.flatten(-2)

    def stacked_input(self, *inputs: torch.Tensor) -> torch.Tensor:
        """The input of several batches' transitions at once, from each batch's
        :meth:`pair_input`: the same as the input of the batches concatenated."""
        if self.concat_inputs:
            return torch.cat(inputs)
        halves = [x.chunk(2, dim=0) for x in inputs]  # pair: each input is (s rows, s' rows)
        return torch.cat([*(first for first, _ in halves), *(second for _, second in halves)])

    def from_input(self, x: torch.Tensor) -> torch.Tensor:
        """Action logits of :meth:`pair_input`'s ``x``."""
        if self.concat_inputs:
            return self.head(self.encoder(x))
        first, second = self.encoder(x).chunk(2, dim=0)
        return self.head(torch.cat([first, second], dim=1))
