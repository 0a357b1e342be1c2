"""LAPO's bottleneck, forward model, decoder and probe (:mod:`abco_train.methods.lapo.method`
maps them to the paper and trains them).

* :class:`VectorQuantiser`: the latent ``z`` (``codebooks * slots * code_dim`` wide) is cut
  into ``codebooks * slots`` vectors; each snaps to the nearest of its codebook's ``codes``
  codes. The codebooks follow the vectors assigned to them by exponential moving averages
  (no gradient reaches them); the loss is the commitment term alone; gradients pass the
  quantisation straight through (``q = sg(q) + z - sg(z)``), as in the authors'
  ``VQEmbeddingEMA``.
* :class:`ForwardModel`: ``f(s, q) -> target of s'``: the run's state encoder (its policy
  network with ``hidden`` outputs) and ``q`` through a two-layer MLP. The target is ``s' - s``
  standardised (vectors) or its average-pooled difference image scaled to unit RMS (frames):
  the authors' model predicts the next frame's pixels with a U-Net, which on this project's
  CPU budget would cost more than every other method's networks together.
* :func:`decoder` (latent -> action logits, an MLP) and :func:`linear_probe_accuracy`.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["VectorQuantiser", "ForwardModel", "decoder", "linear_probe_accuracy"]


class VectorQuantiser(nn.Module):
    """EMA vector quantisation of ``(B, codebooks * slots * code_dim)`` latents.

    Example:
        >>> vq = VectorQuantiser(codebooks=1, slots=2, code_dim=2, codes=3)
        >>> q, loss, codes = vq(torch.zeros(5, 4))
        >>> q.shape, codes.shape, float(loss) >= 0
        (torch.Size([5, 4]), torch.Size([5, 2]), True)
    """

    embedding: torch.Tensor
    ema_count: torch.Tensor
    ema_weight: torch.Tensor

    def __init__(self, codebooks: int, slots: int, code_dim: int, codes: int,
                 commitment: float = 0.05, decay: float = 0.999, eps: float = 1e-5) -> None:
        super().__init__()
        self.shape = (codebooks, slots, code_dim)
        self.commitment, self.decay, self.eps = commitment, decay, eps
        bound = 5.0 / codes  # the authors' uniform initialisation in +-5/codes
        self.register_buffer("embedding", torch.empty(codebooks, codes, code_dim)
                             .uniform_(-bound, bound))  # fmt: skip
        self.register_buffer("ema_count", torch.zeros(codebooks, codes))
        self.register_buffer("ema_weight", self.embedding.clone())

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(q, commitment loss, code indices (B, codebooks * slots))``; in train mode the
        codebooks move towards the vectors assigned to them."""
        g, s, d = self.shape
        x = z.reshape(len(z), g, s, d).transpose(0, 1).reshape(g, -1, d)  # (g, B*s, d)
        flat = x.detach()
        dist = torch.cdist(flat, self.embedding)  # (g, B*s, codes)
        idx = dist.argmin(-1)
        q = torch.gather(self.embedding, 1, idx.unsqueeze(-1).expand(-1, -1, d))
        if self.training:
            self._update(flat, idx)
        loss = self.commitment * F.mse_loss(x, q.detach())
        q = x + (q - x).detach()  # straight through
        q = q.reshape(g, len(z), s, d).transpose(0, 1).reshape(len(z), -1)
        return q, loss, idx.reshape(g, len(z), s).transpose(0, 1).reshape(len(z), -1)

    @torch.no_grad()
    def _update(self, x: torch.Tensor, idx: torch.Tensor) -> None:
        onehot = F.one_hot(idx, self.embedding.shape[1]).to(x.dtype)  # (g, N, codes)
        count = onehot.sum(1)
        self.ema_count.mul_(self.decay).add_(count, alpha=1 - self.decay)
        n = self.ema_count.sum(1, keepdim=True)
        smoothed = (self.ema_count + self.eps) / (n + self.embedding.shape[1] * self.eps) * n
        self.ema_weight.mul_(self.decay).add_(onehot.transpose(1, 2) @ x, alpha=1 - self.decay)
        self.embedding.copy_(self.ema_weight / smoothed.unsqueeze(-1))


class ForwardModel(nn.Module):
    """``f(s, q)``: the state encoder's features and the quantised latent through an MLP."""

    def __init__(self, encoder: nn.Module, features: int, latent: int, hidden: int,
                 out: int) -> None:  # fmt: skip
        super().__init__()
        self.encoder = encoder
        self.head = nn.Sequential(nn.Linear(features + latent, hidden), nn.ReLU(),
                                  nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, out))

    def forward(self, s: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        return self.head(torch.cat([self.encoder(s), q], 1))


def decoder(latent: int, hidden: int, n_actions: int) -> nn.Module:
    """The latent -> action decoder: an MLP of two hidden layers."""
    return nn.Sequential(nn.Linear(latent, hidden), nn.ReLU(), nn.Linear(hidden, hidden),
                         nn.ReLU(), nn.Linear(hidden, n_actions))  # fmt: skip


def linear_probe_accuracy(latents: torch.Tensor, actions: torch.Tensor, n_actions: int,
                          rng: np.random.Generator, steps: int = 500) -> float:  # fmt: skip
    """Held-out accuracy of a linear classifier of ``actions`` from ``latents`` (CPU tensors):
    fitted by Adam (full batch, ``steps`` steps) on a random half, measured on the other.

    Example:
        >>> z = torch.tensor([[1.0], [-1.0]]).repeat(50, 1)
        >>> a = torch.tensor([1, 0]).repeat(50)
        >>> linear_probe_accuracy(z, a, 2, np.random.default_rng(0))
        1.0
    """
    order = torch.from_numpy(rng.permutation(len(latents)))
    train, held = order[: len(order) // 2], order[len(order) // 2 :]
    if len(train) == 0 or len(held) == 0:
        return float("nan")
    x = latents.float()
    mean, std = x[train].mean(0), x[train].std(0).clamp_min(1e-6)
    x = (x - mean) / std
    probe = nn.Linear(x.shape[1], n_actions)
    opt = torch.optim.Adam(probe.parameters(), lr=1e-2)
    for _ in range(steps):
        loss = F.cross_entropy(probe(x[train]), actions[train])
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        return float((probe(x[held]).argmax(1) == actions[held]).float().mean())
