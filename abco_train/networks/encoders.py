"""Encoders: the paper's vector network, its ResNet-18 and a compact CNN for CPU.

Each maps a batch of observations to flat features (``out_features`` of them); the heads of
:mod:`abco_train.networks.heads` turn features into action logits.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from abco_train.networks.layers import ImageInput, SelfAttention2d, Standardise

__all__ = ["FeatureSelfAttention", "VectorEncoder", "CompactCNN", "ResNet18", "conv_stack",
           "stem_stride"]


class FeatureSelfAttention(nn.Module):
    """Self-attention for a feature vector: each of its ``D`` features is one token.

    Feature ``d`` becomes the token ``x_d * e_d + p_d`` (a learned ``E``-dim embedding scaled
    by the value plus a learned position embedding), the tokens form an ``E x D x 1`` map and
    :class:`SelfAttention2d` attends across them (softmax over the ``D`` features, never over
    a single token, which would make the module a linear layer). A learned linear read-out
    maps each token back to one scalar; the result is added as ``x + mu * readout``, ``mu``
    initialised at 0.

    Args:
        features: ``D``.
        embed: ``E``, channels per token.
        reduction: ``k`` of the inner attention.
    """

    def __init__(self, features: int, embed: int = 8, reduction: int = 2) -> None:
        super().__init__()
        self.value_embed = nn.Parameter(torch.randn(embed, features) / embed**0.5)
        self.position_embed = nn.Parameter(torch.randn(embed, features) / embed**0.5)
        self.attention = SelfAttention2d(embed, reduction)
        self.readout = nn.Linear(embed, 1)
        self.mu = self.attention.mu  # one scalar gates the whole module

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x + mu * readout(attention(tokens(x)))`` for ``x`` of shape ``(B, D)``."""
        tokens = x[:, None, :] * self.value_embed + self.position_embed  # (B, E, D)
        attended = self.attention.attend(tokens.unsqueeze(-1))  # (B, E, D, 1)
        return x + self.mu * self.readout(attended.squeeze(-1).transpose(1, 2)).squeeze(-1)


class VectorEncoder(Standardise):
    """The paper's vector network up to its last hidden layer.

    ``input -> FC12 -> SA -> FC12 -> SA -> FC12 -> FC12`` with LeakyReLU after each FC; the
    action layer is added by the policy / IDM head. Inputs are standardised with fixed
    ``mean``/``std`` buffers (from the pre-demonstrations).
    """

    def __init__(self, in_features: int, hidden: int = 12, attention: bool = True) -> None:
        super().__init__(np.zeros(in_features), np.ones(in_features))

        def sa() -> nn.Module:
            return FeatureSelfAttention(hidden) if attention else nn.Identity()

        self.body = nn.Sequential(
            nn.Linear(in_features, hidden), nn.LeakyReLU(), sa(),
            nn.Linear(hidden, hidden), nn.LeakyReLU(), sa(),
            nn.Linear(hidden, hidden), nn.LeakyReLU(),
            nn.Linear(hidden, hidden), nn.LeakyReLU(),
        )  # fmt: skip
        self.out_features = hidden

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Features of standardised ``x``."""
        return self.body(super().forward(x))


def stem_stride(height: int, width: int) -> int:
    """The compact convolutions' first stride (and kernel) for ``height x width`` frames: 4
    from 32 pixels a side (64x64 frames: 16x16 maps), 2 from 16, else 1 (a small symbolic
    grid, MiniGrid's 7x7 view: each cell embedded on its own, none merged).

    Example:
        >>> stem_stride(64, 64), stem_stride(20, 24), stem_stride(7, 7)
        (4, 2, 1)
    """
    side = min(height, width)
    return 4 if side >= 32 else 2 if side >= 16 else 1


def conv_stack(channels: int, activation: type[nn.Module] = nn.LeakyReLU,
               attention: bool | None = True, stride: int = 4) -> nn.Sequential:  # fmt: skip
    """The compact convolutions: ``conv kxk/k (16) -> conv 3x3/2 (32) -> SA -> conv 3x3 (32)
    -> SA -> flatten`` over ``channels`` input channels, ``k = stride``.

    Args:
        channels: Input channels.
        activation: After each convolution.
        attention: ``True``: the two self-attention modules; ``False``: identities in their
            place; ``None``: no slot for them (a plain stack, as GAIfO's learner uses).
        stride: The first convolution's stride and kernel (:func:`stem_stride`; 4 for
            64x64 frames).
    """
    def slot() -> list[nn.Module]:
        if attention is None:
            return []
        return [SelfAttention2d(32) if attention else nn.Identity()]

    return nn.Sequential(
        nn.Conv2d(channels, 16, stride, stride=stride), activation(),
        nn.Conv2d(16, 32, 3, stride=2, padding=1), activation(), *slot(),
        nn.Conv2d(32, 32, 3, padding=1), activation(), *slot(),
        nn.Flatten(),
    )  # fmt: skip


class CompactCNN(nn.Module):
    """A small CNN for 64x64 RGB that trains fast on CPU, with the paper's attention placement;
    it takes frames of any size (:func:`stem_stride`: a 7x7 grid keeps its cells apart).

    ``conv 4x4/4 (16) -> conv 3x3/2 (32) -> SA -> conv 3x3 (32) -> SA -> flatten``: the first
    attention follows the second stage, the second one the last stage, as in the ResNet. The
    features stay spatial (no global pooling), so where the agent's dot is survives.

    ``mean`` and ``std`` (per channel, of frames scaled to ``[0, 1]``) standardise the input
    (:class:`~abco_train.networks.layers.ImageInput`).

    Example:
        >>> CompactCNN((7, 7, 3)).out_features, CompactCNN((64, 64, 3)).out_features
        (512, 2048)
    """

    def __init__(self, image_shape: tuple[int, int, int], attention: bool = True,
                 mean: np.ndarray | None = None, std: np.ndarray | None = None) -> None:
        super().__init__()
        h, w, c = image_shape
        self.input = ImageInput(mean, std)
        self.body = conv_stack(c, nn.LeakyReLU, attention, stem_stride(h, w))
        with torch.no_grad():
            self.out_features = int(self.body(torch.zeros(1, c, h, w)).shape[1])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Flat features of a batch of ``(H, W, C)`` images."""
        return self.body(self.input(x))


class BasicBlock(nn.Module):
    """ResNet basic block: two 3x3 conv + batch norm, identity or 1x1 projection shortcut."""

    def __init__(self, cin: int, cout: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(cout)
        self.shortcut: nn.Module = nn.Identity()
        if stride != 1 or cin != cout:
            self.shortcut = nn.Sequential(
                nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``relu(bn(conv(relu(bn(conv(x))))) + shortcut(x))``."""
        y = torch.relu(self.bn1(self.conv1(x)))
        return torch.relu(self.bn2(self.conv2(y)) + self.shortcut(x))


class ResNet18(nn.Module):
    """ResNet-18 (He et al. 2016) in plain torch, with the paper's two attention modules.

    Stem ``conv 7x7/2 (64) -> maxpool 3x3/2``, then eight basic blocks in four stages of
    ``64, 128, 256, 512`` channels, global average pooling to 512 features. Following the
    paper (``ResBlock_2 -> SA_64 -> ... -> ResBlock_4 -> SA_128``) the attention modules sit
    after the second residual block (the end of the first stage, 64 channels) and after the
    fourth (the end of the second stage, 128 channels). ``mean`` and ``std`` as for
    :class:`CompactCNN`.
    """

    def __init__(self, image_shape: tuple[int, int, int], attention: bool = True,
                 mean: np.ndarray | None = None, std: np.ndarray | None = None) -> None:
        super().__init__()
        c = image_shape[2]
        self.input = ImageInput(mean, std)
        self.stem = nn.Sequential(
            nn.Conv2d(c, 64, 7, 2, 3, bias=False), nn.BatchNorm2d(64), nn.ReLU(),
            nn.MaxPool2d(3, 2, 1),
        )  # fmt: skip
        layers: list[nn.Module] = []
        cin = 64
        for stage, cout in enumerate((64, 128, 256, 512)):
            for block in range(2):
                layers.append(BasicBlock(cin, cout, 2 if stage > 0 and block == 0 else 1))
                cin = cout
                if attention and stage in (0, 1) and block == 1:
                    layers.append(SelfAttention2d(cout))
        self.blocks = nn.Sequential(*layers)
        self.out_features = 512

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """512 pooled features of a batch of ``(H, W, C)`` images."""
        return self.blocks(self.stem(self.input(x))).mean(dim=(2, 3))
