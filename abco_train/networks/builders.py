"""The policy and the IDM of a run, built from one table: architecture name -> builder.

Every network comes in two roles built alike (:mod:`abco_train.networks.heads`): the policy
model maps ``s_t`` to action logits, the inverse dynamics model ``(s_t, s_t+1)``.
``attention=False`` builds the same networks with the self-attention modules left out (the
BCO baselines and the paper's "sampling only" ablations). The encoders are in
:mod:`abco_train.networks.encoders`, the maze-cell networks in :mod:`abco_train.networks.cells`.

Example:
    >>> import torch
    >>> from gymnasium import spaces
    >>> policy, idm = build_networks(spaces.Box(-1, 1, (4,)), 2, arch="mlp")
    >>> policy(torch.zeros(3, 4)).shape, idm(torch.zeros(3, 4), torch.zeros(3, 4)).shape
    (torch.Size([3, 2]), torch.Size([3, 2]))
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from gymnasium import spaces

import abco_envs
from abco_train.config.run import ARCHS, IDM_INPUTS
from abco_train.networks.cells import CELLNET_IDM_ITERATIONS, CellNet, PlannedHead
from abco_train.networks.encoders import CompactCNN, ResNet18, VectorEncoder
from abco_train.networks.heads import IDMNet, PolicyNet, action_head, small_head

__all__ = ["NetworkSpec", "BUILDERS", "build_networks", "default_arch", "image_statistics",
           "frame_statistics", "data_statistics", "MAX_STATISTICS_ROWS"]

#: The most frames :func:`image_statistics` reads (evenly spaced over the data).
MAX_STATISTICS_ROWS = 20_000


@dataclass(frozen=True)
class NetworkSpec:
    """What a builder needs: the observations' shape, the actions, the switches and the
    statistics of the data (see :func:`build_networks`' arguments)."""

    shape: tuple[int, ...]
    n_actions: int
    arch: str
    attention: bool = True
    idm_input: str = "difference"
    hidden: int = 12
    dropout: float = 0.5
    obs_mean: np.ndarray | None = None
    obs_std: np.ndarray | None = None
    delta_mean: np.ndarray | None = None
    delta_std: np.ndarray | None = None
    grid: int | None = None

    @property
    def fused(self) -> bool:
        """Whether the IDM reads one input, the frame and its difference (``difference``)."""
        return self.idm_input == "difference"

    @property
    def idm_shape(self) -> tuple[int, int, int]:
        """The IDM encoder's input: frame and difference channels, or one frame."""
        h, w, c = _image_shape(self.shape)
        return (h, w, 2 * c) if self.fused else (h, w, c)


def _image_shape(shape: tuple[int, ...]) -> tuple[int, int, int]:
    """``(H, W, C)``: the shape of image observations (:func:`build_networks` checks that
    they have three sides)."""
    h, w, c = shape
    return h, w, c


def _vector_networks(spec: NetworkSpec) -> tuple[PolicyNet, IDMNet]:
    """``mlp``: the paper's vector nets, inputs standardised by the data's statistics."""
    if len(spec.shape) != 1:
        raise ValueError(f"arch 'mlp' needs vector observations, got shape {spec.shape}")
    if not spec.fused:
        raise ValueError("vector IDMs read (s, s' - s): idm_input must be 'difference'")
    d = spec.shape[0]
    pm_enc = VectorEncoder(d, spec.hidden, spec.attention)
    idm_enc = VectorEncoder(2 * d, spec.hidden, spec.attention)

    def stat(value: np.ndarray | None, fill: float) -> np.ndarray:
        return np.full(d, fill) if value is None else np.asarray(value, dtype=np.float64)

    mean, dmean = stat(spec.obs_mean, 0.0), stat(spec.delta_mean, 0.0)
    std = np.maximum(stat(spec.obs_std, 1.0), 1e-6)
    dstd = np.maximum(stat(spec.delta_std, 1.0), 1e-6)
    for enc, m, sd in ((pm_enc, mean, std), (idm_enc, np.r_[mean, dmean], np.r_[std, dstd])):
        enc.mean.copy_(torch.as_tensor(m, dtype=torch.float32))
        enc.std.copy_(torch.as_tensor(sd, dtype=torch.float32))
    return (
        PolicyNet(pm_enc, torch.nn.Linear(spec.hidden, spec.n_actions)),
        IDMNet(idm_enc, torch.nn.Linear(spec.hidden, spec.n_actions), concat_inputs=True),
    )


def _cell_networks(spec: NetworkSpec) -> tuple[PolicyNet, IDMNet]:
    """``cellnet`` / ``cellplan``: the maze read cell by cell (:mod:`abco_train.networks.cells`)."""
    if spec.grid is None or not spec.fused:
        raise ValueError(f"arch {spec.arch!r} needs the maze's grid size and idm_input "
                         "'difference'")  # fmt: skip
    pm_enc = CellNet(_image_shape(spec.shape), spec.grid, spec.attention,
                     plan=spec.arch == "cellplan")  # fmt: skip
    # The IDM's move is local (two neighbouring cells): two steps see both cells.
    idm_enc = CellNet(spec.idm_shape, spec.grid, spec.attention,
                      iterations=CELLNET_IDM_ITERATIONS)  # fmt: skip
    pm_head = small_head(pm_enc.out_features, spec.n_actions)
    if pm_enc.planner is not None:
        pm_head = PlannedHead(pm_head, spec.n_actions, pm_enc.planner.gamma)
    return (PolicyNet(pm_enc, pm_head),
            IDMNet(idm_enc, small_head(idm_enc.out_features, spec.n_actions),
                   concat_inputs=True))  # fmt: skip


def _channel_statistics(spec: NetworkSpec
                        ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:  # fmt: skip
    """The image encoders' ``mean``/``std`` keywords (policy, IDM): none without the data's
    statistics; the IDM's fused input is a frame and its difference (both scaled to
    ``[0, 1]``), its ``pair`` input one frame."""
    if spec.obs_mean is None or spec.obs_std is None:
        return {}, {}
    frame = {"mean": np.asarray(spec.obs_mean), "std": np.asarray(spec.obs_std)}
    if not spec.fused or spec.delta_mean is None or spec.delta_std is None:
        return frame, frame
    return frame, {"mean": np.r_[frame["mean"], spec.delta_mean],
                   "std": np.r_[frame["std"], spec.delta_std]}


def image_statistics(frames: np.ndarray, obs_t: np.ndarray) -> dict[str, np.ndarray]:
    """Per-channel mean and std of ``frames`` (scaled to ``[0, 1]`` when ``uint8``, as the
    encoders read them) and of the differences ``s_t+1 - s_t`` of the transitions ``obs_t``:
    :func:`build_networks`' ``obs_mean``, ``obs_std``, ``delta_mean``, ``delta_std`` for
    frames whose values are not pixels (e.g. MiniGrid's symbolic cells). At most
    :data:`MAX_STATISTICS_ROWS` transitions, evenly spaced, are read; a std is at least one
    grey level (1/255).

    Example:
        >>> frames = np.zeros((3, 2, 2, 1), np.uint8); frames[1:] = 51
        >>> {k: v.round(3).tolist() for k, v in image_statistics(frames, np.array([0, 1])).items()}
        {'obs_mean': [0.15], 'obs_std': [0.087], 'delta_mean': [0.1], 'delta_std': [0.1]}
    """
    obs_t = np.asarray(obs_t)
    if len(obs_t) > MAX_STATISTICS_ROWS:
        obs_t = obs_t[np.linspace(0, len(obs_t) - 1, MAX_STATISTICS_ROWS).astype(np.int64)]
    scale = 255.0 if frames.dtype == np.uint8 else 1.0
    s = np.asarray(frames[obs_t], dtype=np.float64) / scale
    s1 = np.asarray(frames[obs_t + 1], dtype=np.float64) / scale
    rows = np.concatenate([s, s1]).reshape(-1, frames.shape[-1])
    deltas = (s1 - s).reshape(-1, frames.shape[-1])
    floor = 1.0 / 255.0
    return {"obs_mean": rows.mean(0), "obs_std": np.maximum(rows.std(0), floor),
            "delta_mean": deltas.mean(0), "delta_std": np.maximum(deltas.std(0), floor)}


def frame_statistics(env_id: str, frames: Any, obs_t: np.ndarray) -> dict[str, Any]:
    """What :func:`build_networks` needs of a run's frames beyond their shape: a maze's
    ``grid`` (its cells per side, for the cell networks); another env's
    :func:`image_statistics` of ``frames`` (the pre-demonstrations) at transitions ``obs_t``."""
    if abco_envs.is_maze(env_id):
        return {"grid": abco_envs.maze_size(env_id)}
    return image_statistics(np.asarray(frames), obs_t)


def data_statistics(env_id: str, pre_obs: Any, pre_t: np.ndarray, part: bool = False
                    ) -> dict[str, Any]:  # fmt: skip
    """:func:`build_networks`' statistics keywords from the pre-demonstrations a run trains on.

    Vector states: the mean and std of the states and of ``s_t+1 - s_t`` over the transitions
    ``pre_t`` (``part``: only the states of those transitions, the ones a ``--budget`` paid
    for; else every row). Frames: :func:`frame_statistics`.

    Example:
        >>> obs = np.array([[0.0], [1.0], [3.0]])
        >>> stats = data_statistics("CartPole-v1", obs, np.array([0, 1]))
        >>> {k: v.round(3).tolist() for k, v in stats.items()}  # doctest: +NORMALIZE_WHITESPACE
        {'obs_mean': [1.333], 'obs_std': [1.247], 'delta_mean': [1.5], 'delta_std': [0.5]}
    """
    if len(pre_obs.shape) != 2:  # frames: a maze's grid (cell by cell), another env's channels
        return frame_statistics(env_id, pre_obs, pre_t)
    rows = np.unique(np.concatenate([pre_t, pre_t + 1])) if part else slice(None)
    states = pre_obs[rows].astype(np.float64)
    deltas = pre_obs[pre_t + 1].astype(np.float64) - pre_obs[pre_t]
    return {"obs_mean": states.mean(0), "obs_std": states.std(0),
            "delta_mean": deltas.mean(0), "delta_std": deltas.std(0)}  # fmt: skip


def _compact_networks(spec: NetworkSpec) -> tuple[PolicyNet, IDMNet]:
    """``cnn``: the compact CNN (CPU default for frames)."""
    pm_stats, idm_stats = _channel_statistics(spec)
    pm_enc = CompactCNN(_image_shape(spec.shape), spec.attention, **pm_stats)
    idm_enc = CompactCNN(spec.idm_shape, spec.attention, **idm_stats)
    idm_features = idm_enc.out_features * (1 if spec.fused else 2)
    pm_head = small_head(pm_enc.out_features, spec.n_actions)
    idm_head = small_head(idm_features, spec.n_actions)
    return PolicyNet(pm_enc, pm_head), IDMNet(idm_enc, idm_head, concat_inputs=spec.fused)


def _resnet_networks(spec: NetworkSpec) -> tuple[PolicyNet, IDMNet]:
    """``resnet18``: the paper's image networks with its dropout heads."""
    pm_stats, idm_stats = _channel_statistics(spec)
    pm_enc = ResNet18(_image_shape(spec.shape), spec.attention, **pm_stats)
    idm_enc = ResNet18(spec.idm_shape, spec.attention, **idm_stats)
    idm_features = idm_enc.out_features * (1 if spec.fused else 2)
    return (
        PolicyNet(pm_enc, action_head(512, 512, spec.n_actions, spec.dropout)),
        IDMNet(idm_enc, action_head(idm_features, idm_features, spec.n_actions, spec.dropout),
               concat_inputs=spec.fused),
    )  # fmt: skip


#: Architecture name -> builder of ``(policy, IDM)`` (:data:`abco_train.config.run.ARCHS`).
BUILDERS: dict[str, Callable[[NetworkSpec], tuple[PolicyNet, IDMNet]]] = {
    "mlp": _vector_networks,
    "cnn": _compact_networks,
    "resnet18": _resnet_networks,
    "cellnet": _cell_networks,
    "cellplan": _cell_networks,
}


def default_arch(observation_space: spaces.Space) -> str:
    """``mlp`` for 1-D observations, ``cnn`` for images."""
    return "mlp" if len(observation_space.shape or ()) == 1 else "cnn"


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
        arch: One of :data:`~abco_train.config.run.ARCHS`; ``None`` picks ``mlp`` or ``cnn``
            from the space.
        attention: Include the self-attention modules.
        idm_input: How the IDM reads a transition, ``difference`` or ``pair`` (frames only;
            see :class:`~abco_train.networks.heads.IDMNet`).
        hidden: Width of the vector nets (the paper: 12).
        dropout: Dropout of the ResNet heads (the paper: 0.5).
        obs_mean: Per-feature mean for standardising vector states; for frames (``cnn``,
            ``resnet18``), per channel (:func:`image_statistics`; none: frames scaled to
            ``[0, 1]`` only, as for the mazes).
        obs_std: Per-feature (frames: per-channel) std.
        delta_mean: Per-feature mean of ``s_t+1 - s_t`` (the vector IDM's second half; the
            frame IDM's difference channels).
        delta_std: Per-feature std of ``s_t+1 - s_t``.
        grid: Cells per side of the maze (the cell networks need it).

    Raises:
        ValueError: Unknown ``arch`` or one that does not fit the space.
    """
    arch = arch or default_arch(observation_space)
    shape = tuple(observation_space.shape or ())
    if arch not in BUILDERS:
        raise ValueError(f"unknown arch {arch!r}; expected one of {ARCHS}")
    if arch != "mlp" and len(shape) != 3:
        raise ValueError(f"arch {arch!r} needs (H, W, C) image observations, got shape {shape}")
    if arch != "mlp" and idm_input not in IDM_INPUTS:
        raise ValueError(f"unknown idm_input {idm_input!r}; expected one of {IDM_INPUTS}")
    spec = NetworkSpec(shape, n_actions, arch, attention, idm_input, hidden, dropout, obs_mean,
                       obs_std, delta_mean, delta_std, grid)  # fmt: skip
    return BUILDERS[arch](spec)
