"""Networks of ABCO: SAGAN self-attention, the paper's vector nets, its ResNet-18, a compact
CNN, and :func:`build_networks`, which also builds the networks for unseen maze layouts
(:mod:`abco_train.networks.cells`).

Every network comes in two roles built from the same encoder:

* the *policy model* (PM) maps one state ``s_t`` to action logits;
* the *inverse dynamics model* (IDM) maps a pair ``(s_t, s_t+1)`` to action logits.

``attention=False`` builds the same network with the self-attention modules left out (the
BCO baselines and the paper's "sampling only" ablations).

Example:
    >>> import torch
    >>> from gymnasium import spaces
    >>> policy, idm = build_networks(spaces.Box(-1, 1, (4,)), 2, arch="mlp")
    >>> policy(torch.zeros(3, 4)).shape, idm(torch.zeros(3, 4), torch.zeros(3, 4)).shape
    (torch.Size([3, 2]), torch.Size([3, 2]))
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces
from torch import nn

from abco_train.config.run import ARCHS, CELL_ARCHS, IDM_INPUTS
from abco_train.networks.cells import CELLNET_IDM_ITERATIONS, CellNet, PlannedHead
from abco_train.networks.layers import SelfAttention2d, image_input

__all__ = [
    "ARCHS",
    "IDM_INPUTS",
    "image_input",
    "SelfAttention2d",
    "FeatureSelfAttention",
    "VectorEncoder",
    "CompactCNN",
    "ResNet18",
    "PolicyNet",
    "IDMNet",
    "build_networks",
]



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


class VectorEncoder(nn.Module):
    """The paper's vector network up to its last hidden layer.

    ``input -> FC12 -> SA -> FC12 -> SA -> FC12 -> FC12`` with LeakyReLU after each FC; the
    action layer is added by the policy / IDM head. Inputs are standardised with fixed
    ``mean``/``std`` buffers (from the pre-demonstrations).
    """

    def __init__(self, in_features: int, hidden: int = 12, attention: bool = True) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(in_features))
        self.register_buffer("std", torch.ones(in_features))

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
        return self.body((x.float() - self.mean) / self.std)


class CompactCNN(nn.Module):
    """A small CNN for 64x64 RGB that trains fast on CPU, with the paper's attention placement.

    ``conv 4x4/4 (16) -> conv 3x3/2 (32) -> SA -> conv 3x3 (32) -> SA -> flatten``: the first
    attention follows the second stage, the second one the last stage, as in the ResNet. The
    features stay spatial (no global pooling), so where the agent's dot is survives.
    """

    def __init__(self, image_shape: tuple[int, int, int], attention: bool = True) -> None:
        super().__init__()
        h, w, c = image_shape
        self.body = nn.Sequential(
            nn.Conv2d(c, 16, 4, stride=4), nn.LeakyReLU(),
            nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.LeakyReLU(),
            SelfAttention2d(32) if attention else nn.Identity(),
            nn.Conv2d(32, 32, 3, padding=1), nn.LeakyReLU(),
            SelfAttention2d(32) if attention else nn.Identity(),
            nn.Flatten(),
        )  # fmt: skip
        with torch.no_grad():
            self.out_features = int(self.body(torch.zeros(1, c, h, w)).shape[1])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Flat features of a batch of ``(H, W, C)`` images."""
        return self.body(image_input(x))


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
    fourth (the end of the second stage, 128 channels).
    """

    def __init__(self, image_shape: tuple[int, int, int], attention: bool = True) -> None:
        super().__init__()
        c = image_shape[2]
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
        return self.blocks(self.stem(image_input(x))).mean(dim=(2, 3))


def _head(in_features: int, hidden: int | None, n_actions: int, dropout: float) -> nn.Module:
    """The action layer; with ``hidden`` the paper's ``FC -> LeakyReLU -> Dropout`` stack."""
    if hidden is None:
        return nn.Linear(in_features, n_actions)
    return nn.Sequential(
        nn.Linear(in_features, hidden), nn.LeakyReLU(), nn.Dropout(dropout),
        nn.Linear(hidden, 512), nn.LeakyReLU(), nn.Dropout(dropout),
        nn.Linear(512, n_actions),
    )  # fmt: skip


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
        if self.concat_inputs:
            if obs.dtype == torch.uint8:  # frames: a signed difference needs floats
                obs, next_obs = obs.float().div_(255.0), next_obs.float().div_(255.0)
            return self.head(self.encoder(torch.cat([obs, next_obs - obs], dim=-1)))
        both = self.encoder(torch.cat([obs, next_obs], dim=0))
        first, second = both.chunk(2, dim=0)
        return self.head(torch.cat([first, second], dim=1))


def default_arch(observation_space: spaces.Space) -> str:
    """``mlp`` for 1-D observations, ``cnn`` for images."""
    return "mlp" if len(observation_space.shape) == 1 else "cnn"


def build_networks(
    observation_space: spaces.Space,
    n_actions: int,
    arch: str | None = None,
    attention: bool = True,
    idm_input: str = "difference",
    hidden: int = 12,
    dropout: float = 0.5,
    obs_mean: np.ndarray | None = None,
    obs_std: np.ndarray | None = None,
    delta_mean: np.ndarray | None = None,
    delta_std: np.ndarray | None = None,
    grid: int | None = None,
) -> tuple[PolicyNet, IDMNet]:
    """The policy and the IDM for an observation space.

    Args:
        observation_space: A 1-D ``Box`` (vector states) or an ``(H, W, C)`` image ``Box``.
        n_actions: Number of discrete actions.
        arch: One of :data:`ARCHS`; ``None`` picks ``mlp`` or ``cnn`` from the space.
        attention: Include the self-attention modules.
        idm_input: How the IDM reads a transition, ``difference`` or ``pair`` (frames only;
            see :class:`IDMNet`).
        hidden: Width of the vector nets (the paper: 12).
        dropout: Dropout of the ResNet heads (the paper: 0.5).
        obs_mean: Per-feature mean for standardising vector states.
        obs_std: Per-feature std for standardising vector states.
        delta_mean: Per-feature mean of ``s_t+1 - s_t`` (the vector IDM's second half).
        delta_std: Per-feature std of ``s_t+1 - s_t``.
        grid: Cells per side of the maze (``cellnet`` only, which needs it).

    Raises:
        ValueError: Unknown ``arch`` or one that does not fit the space.
    """
    arch = arch or default_arch(observation_space)
    shape = tuple(observation_space.shape)
    if arch == "mlp":
        if len(shape) != 1:
            raise ValueError(f"arch 'mlp' needs vector observations, got shape {shape}")
        if idm_input != "difference":
            raise ValueError("vector IDMs read (s, s' - s): idm_input must be 'difference'")
        pm_enc = VectorEncoder(shape[0], hidden, attention)
        idm_enc = VectorEncoder(2 * shape[0], hidden, attention)
        d = shape[0]

        def stat(value: np.ndarray | None, fill: float) -> np.ndarray:
            return np.full(d, fill) if value is None else np.asarray(value, dtype=np.float64)

        mean, dmean = stat(obs_mean, 0.0), stat(delta_mean, 0.0)
        std = np.maximum(stat(obs_std, 1.0), 1e-6)
        dstd = np.maximum(stat(delta_std, 1.0), 1e-6)
        for enc, m, sd in ((pm_enc, mean, std), (idm_enc, np.r_[mean, dmean], np.r_[std, dstd])):
            enc.mean.copy_(torch.as_tensor(m, dtype=torch.float32))
            enc.std.copy_(torch.as_tensor(sd, dtype=torch.float32))
        return (
            PolicyNet(pm_enc, nn.Linear(hidden, n_actions)),
            IDMNet(idm_enc, nn.Linear(hidden, n_actions), concat_inputs=True),
        )
    if len(shape) != 3:
        raise ValueError(f"arch {arch!r} needs (H, W, C) image observations, got shape {shape}")
    if idm_input not in IDM_INPUTS:
        raise ValueError(f"unknown idm_input {idm_input!r}; expected one of {IDM_INPUTS}")
    fused = idm_input == "difference"
    idm_shape = (*shape[:2], 2 * shape[2]) if fused else shape  # frame + difference channels
    if arch in CELL_ARCHS:
        if grid is None or not fused:
            raise ValueError(f"arch {arch!r} needs the maze's grid size and idm_input "
                             "'difference'")  # fmt: skip
        plan = arch == "cellplan"
        pm_enc = CellNet(shape, grid, attention, plan=plan)
        # The IDM's move is local (two neighbouring cells): two steps see both cells.
        idm_enc = CellNet(idm_shape, grid, attention, iterations=CELLNET_IDM_ITERATIONS)

        def head(features: int) -> nn.Module:
            return nn.Sequential(nn.Linear(features, 128), nn.LeakyReLU(),
                                 nn.Linear(128, n_actions))  # fmt: skip

        pm_head = head(pm_enc.out_features)
        if pm_enc.planner is not None:
            pm_head = PlannedHead(pm_head, n_actions, pm_enc.planner.gamma)
        return (PolicyNet(pm_enc, pm_head),
                IDMNet(idm_enc, head(idm_enc.out_features), concat_inputs=True))  # fmt: skip
    encoder = {"cnn": CompactCNN, "resnet18": ResNet18}.get(arch)
    if encoder is None:
        raise ValueError(f"unknown arch {arch!r}; expected one of {ARCHS}")
    pm_enc, idm_enc = encoder(shape, attention), encoder(idm_shape, attention)
    idm_features = idm_enc.out_features * (1 if fused else 2)
    if arch == "cnn":
        pm_head = nn.Sequential(
            nn.Linear(pm_enc.out_features, 128), nn.LeakyReLU(), nn.Linear(128, n_actions)
        )
        idm_head = nn.Sequential(
            nn.Linear(idm_features, 128), nn.LeakyReLU(), nn.Linear(128, n_actions)
        )
        return PolicyNet(pm_enc, pm_head), IDMNet(idm_enc, idm_head, concat_inputs=fused)
    return (
        PolicyNet(pm_enc, _head(512, 512, n_actions, dropout)),
        IDMNet(idm_enc, _head(idm_features, idm_features, n_actions, dropout),
               concat_inputs=fused),
    )  # fmt: skip
