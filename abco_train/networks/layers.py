"""Layers the networks share: SAGAN self-attention over a feature map, the frame-to-tensor
conversion, and fixed standardisation of vector inputs (:mod:`abco_train.networks.encoders`,
:mod:`abco_train.networks.cells`, and the methods' own networks)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

__all__ = ["SelfAttention2d", "image_input", "Standardise", "standardise", "ImageInput"]

#: Attention over fewer positions than this takes its softmax over a leading dim
#: (:meth:`SelfAttention2d.attend` says why): the 16 floats of an AVX-512 register.
SHORT_SOFTMAX = 16


class SelfAttention2d(nn.Module):
    """SAGAN self-attention over the ``N = H * W`` positions of a feature map.

    ``f = W_f x`` (key), ``g = W_g x`` (query), ``h = W_h x`` (value) are 1x1 convolutions to
    ``C / k`` channels; ``beta_{j,i} = softmax_i(f(x_i)^T g(x_j))``;
    ``a_j = W_v sum_i beta_{j,i} h(x_i)`` (a 1x1 convolution back to ``C`` channels); the
    output is ``x + mu * a`` with ``mu`` a learnable scalar initialised at 0, so the module is
    the identity at initialisation (Eqs. 7-8 of the paper).

    Args:
        channels: ``C``.
        reduction: ``k``; the key/query/value width is ``max(1, C // k)``.
    """

    def __init__(self, channels: int, reduction: int = 8) -> None:
        super().__init__()
        inner = max(1, channels // reduction)
        # 1x1 convolutions are per-position linear maps; nn.Linear on the (B, N, C) tokens
        # computes exactly that and avoids oneDNN's slow path for tiny 1x1 convs on CPU.
        self.key = nn.Linear(channels, inner)
        self.query = nn.Linear(channels, inner)
        self.value = nn.Linear(channels, inner)
        self.out = nn.Linear(inner, channels)
        self.mu = nn.Parameter(torch.zeros(()))

    def attend(self, x: torch.Tensor) -> torch.Tensor:
        """The attention feature map ``a`` (before weighting by ``mu``), same shape as ``x``."""
        b, c, h, w = x.shape
        tokens = x.flatten(2).transpose(1, 2)  # (B, N, C): one token per position
        key, query, value = self.key(tokens), self.query(tokens), self.value(tokens)
        if h * w < SHORT_SOFTMAX:
            # torch's CPU softmax over a dim shorter than one vector register runs element by
            # element when that dim is last (about 3x slower fore and back at the vector
            # encoder's 12 features), and on a few lanes when it is the middle one; laid out
            # (i, B, j), the softmax over the leading i has B * N lanes to vectorise over
            scores_t = torch.bmm(key, query.transpose(1, 2))  # s[b, i, j] = f(x_i) . g(x_j)
            beta_t = torch.softmax(scores_t.permute(1, 0, 2).contiguous(), dim=0)  # over i
            beta = beta_t.permute(1, 2, 0)  # (B, j, i)
        else:
            scores = torch.bmm(query, key.transpose(1, 2))  # s[j, i] = g(x_j) . f(x_i)
            beta = torch.softmax(scores, dim=-1)  # over the attended positions i
        mixed = torch.bmm(beta, value)  # (B, N, C'): sum_i beta_ji h(x_i)
        return self.out(mixed).transpose(1, 2).reshape(b, c, h, w)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x + mu * a(x)``."""
        return x + self.mu * self.attend(x)


def image_input(x: torch.Tensor) -> torch.Tensor:
    """``(B, H, W, C)`` images (uint8, or float in ``[-1, 1]``) -> ``(B, C, H, W)`` float."""
    if x.dtype == torch.uint8:
        x = x.float().div_(255.0)
    return x.permute(0, 3, 1, 2)


def standardise(x: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """``(x - mean) / std`` in float32."""
    return (x.float() - mean) / std


class Standardise(nn.Module):
    """``(x - mean) / std`` with fixed buffers ``mean`` and ``std`` (statistics of the data,
    saved with the network's state)."""

    mean: torch.Tensor  # the buffers, typed (register_buffer sets them)
    std: torch.Tensor

    def __init__(self, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Standardised ``x``."""
        return standardise(x, self.mean, self.std)


class ImageInput(nn.Module):
    """:func:`image_input`, then, given the data's per-channel ``mean`` and ``std`` (of frames
    scaled as :func:`image_input` scales them), each channel standardised: a frame whose
    values are not pixels (MiniGrid's symbolic cells, small integers: below 0.05 once divided
    by 255) reaches the convolutions on the scale they learn at. Without statistics it is
    :func:`image_input` alone and holds no buffers (the mazes' networks)."""

    mean: torch.Tensor | None
    std: torch.Tensor | None

    def __init__(self, mean: np.ndarray | None = None, std: np.ndarray | None = None) -> None:
        super().__init__()
        if mean is None or std is None:
            self.mean = self.std = None
            return
        shape = (1, -1, 1, 1)  # (B, C, H, W): one value per channel
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32).reshape(shape))
        self.register_buffer("std", torch.as_tensor(std, dtype=torch.float32).reshape(shape))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, H, W, C)`` frames -> ``(B, C, H, W)`` floats (standardised, given statistics)."""
        x = image_input(x)
        if self.mean is None or self.std is None:
            return x
        return (x.float() - self.mean) / self.std
