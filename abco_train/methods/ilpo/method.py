"""ILPO: Imitating Latent Policies from Observation (Edwards, Sahni, Schroecker, Isbell, ICML 2019).

ILPO learns from the expert's states alone, without pre-demonstrations: it assumes ``k``
latent actions ``z``, learns what each one does and which one the expert takes, and only then
spends a few environment steps learning which real action each latent action is. Where each
part of the paper lives here:

* **Latent forward model** ``G(E(s), z)``, ``z = 1..k`` (Sec. 3.1; :class:`VectorForwardModel`,
  :class:`ImageForwardModel`): predicts the change ``Delta(s, s')`` that latent action ``z``
  makes from ``s``. Trained on the expert pairs with the **min-over-latents loss**
  (:func:`min_over_latents_loss`)

      L_min = min_z || Delta(s, s') - G(E(s), z) ||^2

  only the latent that already explains a transition best moves towards it, so the ``k``
  latents specialise into the distinct outcomes in the demonstrations. (The squared error is
  averaged over the target's features, which only rescales it. Option ``relax`` adds
  ``relax * mean_z ||.||^2``, the relaxed winner-takes-all of multiple-choice learning; default
  0, the paper's loss.)
* **Latent policy** ``pi(z | s)`` (Sec. 3.2; :func:`latent_policy`, a network of its own):
  trained so that the expected prediction matches the observed change
  (:func:`expected_prediction_loss`)

      L_exp = || Delta(s, s') - sum_z pi(z | s) G(E(s), z) ||^2

  ILPO minimises ``L_min + L_exp`` (:meth:`ILPO._train_latent_model`); as in the authors'
  code the predictions inside the expectation are held fixed, so ``L_exp`` trains ``pi`` and
  ``L_min`` trains ``G``. Option ``exp_weight`` lets that fraction of ``L_exp``'s gradient
  reach ``G`` as well (default 0). With ``exp_weight`` 0 the two losses share no parameter,
  so training them together only makes ``pi`` chase a moving ``G``; option ``policy_steps``
  (mazes: 1000; classic control: ``None``, the joint schedule) trains ``G`` alone for
  ``train_steps`` steps first, then ``pi`` alone for ``policy_steps`` steps of ``L_exp``
  against the trained, fixed ``G``: the same two losses, minimised one after the other. Why:
  on the mazes, in the first ~100 joint steps ``G``'s latents mean nothing yet, ``L_exp``
  drives ``pi`` onto whichever latent's prediction is nearest the mean change, in every
  state; Adam keeps growing those logits while their gradient vanishes, ``pi``'s softmax
  saturates (``max_z pi = 1.00``) and never leaves that latent, so the policy takes one
  action everywhere (5x5 maze: validation seeds 103 and 106 of 100-107, grid seeds 1-3 of
  0-3; docs/training.md). ``exp_weight`` does not apply in this schedule.
* **Action remapping** (Sec. 3.3; :meth:`ILPO._collect`, :meth:`ILPO._fit_remap`): the agent
  acts in the environment, ``a = argmax_a P(a | s, z)`` for ``z = argmax_z pi(z | s)``
  (:meth:`ILPO.act`), epsilon-greedy; for every step ``(s, a, s')`` it finds the latent that
  explains it, ``z* = argmin_z || Delta(s, s') - G(E(s), z) ||^2``, and fits ``P(a | s, z*)``
  by cross-entropy: a small classifier, as the authors' remapping network, reading (detached)
  ``onehot(z)``, ``E(s)`` and what ``z`` does in ``s``, ``G(E(s), z) - mean_z' G(E(s), z')``
  (``remap_input``; see :meth:`ILPO._remap_input` for why), or a count table ``P(a | z*)``
  (``remap="table"``). Every such step is counted as a ``remapping`` interaction
  (:meth:`~abco_train.methods.base.Method.count`). A step that no latent explains clearly (the best
  latent's error is not below ``remap_margin`` times the second best's: an action the expert
  never took, or a move into a maze wall, which changes nothing) says nothing about the
  mapping and is left out of the fit (it is still counted); ``remap_margin`` is 0.1 for
  classic control, 0.5 for mazes.

What ``G`` predicts, and with what:

* **Vector states**: ``Delta = s' - s`` standardised per feature with the expert pairs' mean
  and standard deviation (inputs standardised likewise). ``E`` is a two-layer MLP; ``z``'s
  learnt embedding is added to a linear map of ``E(s)`` (a linear layer over
  ``concat(E(s), onehot(z))``, the authors' design) and two layers predict ``Delta``.
* **Frames** (mazes, 64x64 RGB): the difference image ``s' - s`` (in ``[-1, 1]``),
  average-pooled by ``pool`` (8x8 maps up to 5x5 mazes, 16x16 for 10x10: at least ~1.6 pixels
  per cell) and divided by its RMS over the expert pairs. ``G`` is fully convolutional on that
  grid (``E``: a strided convolution and three dilated 3x3 convolutions; ``z``'s embedding
  added to every position's channels; two 3x3 convolutions out). Why this target: a fixed,
  downsampled difference cannot collapse the way a learnt embedding target can (an encoder
  mapping every frame to one point predicts it perfectly); it is zero everywhere but at the
  agent's old and new cell, which pooling keeps; it is computed once for all pairs; and it is
  small (192 or 768 values per latent instead of a 64x64x3 frame), so ``G`` trains in about a
  minute on one CPU thread. Why convolutional: with one set of filters at every position a
  latent action means the same move wherever the agent is; an MLP head over flat features
  (tried first) let latent 0 mean "down" in one cell and "right" in another.
* **Cells** (``target="cells"``, the 10x10 maze's default): a 10x10 maze's cells are 6 or 7
  pixels wide, so a fixed pooling cuts each at another offset and one move's pooled
  difference looks different in every cell. This target is how much each cell changed, the
  sum of ``|s' - s|`` over the cell's pixels and the channels (:class:`CellAverage`, at the
  renderer's cell borders), one value per cell: a move is the same two cells' change
  wherever it is made, whatever the cells' sizes (and the goal's colour changes only how
  much). ``G`` is then local: ``E`` is a 3x3 convolution at full resolution averaged over
  each cell and a 1x1 convolution, and the head one 3x3 convolution over cells, so a cell's
  prediction sees its neighbours only. A global ``G`` can learn where the deterministic
  expert goes next from the whole maze, and its latents need not stand for moves; a local
  one cannot, so they must (docs/training.md).

Identifiability (why the remapping reads ``s``): a deterministic expert shows one action per
state, so the min-over-latents loss cannot tell "latent 0 = left here, latent 0 = right
there" from a consistent assignment; what ties a latent's meaning across states is ``G``'s
smoothness. Where it does not hold, ``P(a | s, z)`` still maps each latent by what it does in
that state. ``latent_init="shared"`` starts every latent from one embedding plus
``split_noise`` (they split on what the shared prediction leaves unexplained); default
``random``.

Schedule (the harness calls :meth:`ILPO.train_iteration` for ``i = 0..iterations`` and
evaluates greedily after each): iteration 0 trains ``G`` and ``pi`` for ``train_steps`` Adam
steps (``--lr``, minibatches of ``--batch-size`` expert pairs; with ``policy_steps``, ``G``
for ``train_steps`` then ``pi`` for ``policy_steps``), then takes the first
``remap_steps`` environment steps with uniformly random actions (no mapping exists yet, and
every action gets tried) and fits the remapping; every later iteration may train ``G`` and
``pi`` for ``later_steps`` more steps (default 0; with ``policy_steps``, ``G`` then ``pi``,
``later_steps`` each), takes ``remap_steps`` more environment
steps, epsilon-greedy (``remap_epsilon``) with the current mapping, and refits the
remapping on all the kept steps so far (``remap_epochs`` epochs). The steps run in a vector
env of ``remap_envs`` slots of their own (:func:`abco_train.harness.rollouts.make_vector_env`, reset
from the run's generator; mazes: the train split's layouts from the start cell, cycling
through them, episodes cut after ``remap_max_steps``, default ``4 n^2``); the step after an
episode ends is the env's reset, not a transition, and is neither kept nor counted. ILPO
learns nothing from the evaluation runs (no post-demonstrations) and uses no
pre-demonstrations (it counts none).

Diagnostics (``metrics.jsonl``, every iteration, on the expert's states):
``latent_usage`` (how often each latent is ``z*``), ``policy_latent_usage`` (how often each
latent is ``argmax_z pi``), ``policy_latent_agreement`` (``argmax_z pi = z*``),
``expert_label_accuracy`` (the inferred labels, the remapped ``z*`` that
:meth:`ILPO.expert_labels` returns, against the true actions: it measures ``G`` and the
remapping, not the policy) and ``policy_action_accuracy`` (what :meth:`ILPO.act`, the
evaluated policy, does in the expert's states against the expert's actions). The true
actions are a measurement only, never used for training or for a choice.

Options (``--method-options``; defaults in :data:`OPTION_DEFAULTS` by env kind, then
:data:`ENV_OPTION_DEFAULTS` by env, checked by :meth:`ILPO.options`): ``latents`` (``k``,
default the env's number of actions), ``train_steps``, ``policy_steps``, ``later_steps``,
``hidden``, ``channels``, ``pool``, ``target``, ``exp_weight``, ``relax``, ``latent_init``,
``split_noise``, ``remap``, ``remap_input``, ``remap_steps``, ``remap_envs``,
``remap_epsilon``, ``remap_margin``, ``remap_epochs``, ``remap_max_steps``. All randomness
comes from the run's generator and from torch (seeded by the harness): the same seed gives the
same run on CPU.

It is registered through :func:`abco_train.methods.registry.register` like any plugin. The losses
and
networks are in :mod:`abco_train.methods.ilpo.networks` (imported here under the same names).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

import abco_envs
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.rollouts import make_vector_env
from abco_train.harness.training_data import TrainingData
from abco_train.methods.base import Method
from abco_train.methods.ilpo.networks import (
    CellAverage,
    ILPONet,
    ImageForwardModel,
    RemapNet,
    VectorForwardModel,
    expected_prediction_loss,
    latent_errors,
    latent_policy,
    min_over_latents_loss,
)
from abco_train.methods.registry import register

__all__ = ["ILPO", "CellAverage", "ILPONet", "VectorForwardModel", "ImageForwardModel",
           "latent_policy", "min_over_latents_loss", "expected_prediction_loss", "latent_errors",
           "OPTION_DEFAULTS", "ENV_OPTION_DEFAULTS"]  # fmt: skip

#: ILPO's options by env kind (``None``: decided from the env, see :meth:`ILPO.options`).
#: Classic control keeps only the remapping steps whose best latent explains them 10 times
#: better than the second best (``remap_margin`` 0.1, was 0.5): on Acrobot the latent model
#: tells the torques apart in ~99% of the expert's states, but the steps it explains only 2-10
#: times better than the next latent are noisy labels, and the remapping, not the model, was
#: what lost accuracy (docs/training.md, validation seeds 100-102). Mazes train ``pi`` after
#: ``G`` (``policy_steps`` 1000; module docstring): trained together, ``pi`` saturated on one
#: latent in most 5x5 seeds (docs/training.md, validation seeds 100-107).
OPTION_DEFAULTS: dict[str, dict[str, Any]] = {
    "classic": {
        "latents": None, "train_steps": 3000, "policy_steps": None, "later_steps": 0,
        "hidden": 64, "channels": 16, "pool": 1, "target": "pooled", "exp_weight": 0.0,
        "relax": 0.0,
        "latent_init": "random", "split_noise": 0.01, "remap": "state",
        "remap_input": "effect+embedding",
        "remap_steps": 500, "remap_envs": 10, "remap_epsilon": 0.2, "remap_margin": 0.1,
        "remap_epochs": 20, "remap_max_steps": None,
    },
    "maze": {
        "latents": None, "train_steps": 1300, "policy_steps": 1000, "later_steps": 0,
        "hidden": 128, "channels": 16, "pool": 4, "target": "pooled", "exp_weight": 0.0,
        "relax": 0.0,
        "latent_init": "random", "split_noise": 0.01, "remap": "state",
        "remap_input": "effect+embedding",
        "remap_steps": 1000, "remap_envs": 50, "remap_epsilon": 0.2, "remap_margin": 0.5,
        "remap_epochs": 20, "remap_max_steps": None,
    },
}  # fmt: skip

#: Per-environment changes on top of :data:`OPTION_DEFAULTS`.
ENV_OPTION_DEFAULTS: dict[str, dict[str, Any]] = {
    # Acrobot remaps from 1,000 steps a round (31 rounds at its alpha = 30: 31,000 steps):
    # validation seeds 100-115, mean AER -78.4 against -87.2 with 500 (docs/training.md).
    "Acrobot-v1": {"remap_steps": 1000},
    # Pooled frames keep at least ~1.6 pixels per cell: 8x8 maps up to 5x5, 16x16 for 10x10.
    "AbcoMaze3x3-v0": {"pool": 8},
    "AbcoMaze5x5-v0": {"pool": 8},
    # 10x10 (docs/training.md, "ILPO on the 10x10 maze"): cells 6-7 pixels wide, which no
    # fixed pooling keeps whole, so G predicts how much each cell changes (``target``
    # "cells", a local G); its latents then mean one move everywhere, and a table maps them.
    "AbcoMaze10x10-v0": {"pool": 4, "target": "cells", "relax": 0.05, "remap": "table",
                         "policy_steps": 10000},
}

_REMAP_MODES = ("state", "table")
_TARGETS = ("pooled", "cells")
_REMAP_INPUTS = ("effect+embedding", "effect", "embedding")


# -- the method -----------------------------------------------------------------------------


@register("ilpo")
class ILPO(Method):
    """ILPO (see the module docstring): latent forward model and policy, then remapping."""

    @classmethod
    def options(cls, config: RunConfig, n_actions: int) -> dict[str, Any]:
        """ILPO's options for a run: its env kind's defaults, its env's, then the user's.

        Raises:
            ConfigError: An unknown option or a value out of range.
        """
        kind = "maze" if abco_envs.is_maze(abco_envs.env_name(config.env)) else "classic"
        opts = {**OPTION_DEFAULTS[kind],
                **ENV_OPTION_DEFAULTS.get(abco_envs.env_name(config.env), {})}  # fmt: skip
        unknown = sorted(set(config.method_options) - set(opts))
        if unknown:
            raise ConfigError(f"unknown ilpo option(s) {unknown}; known: {sorted(opts)}")
        opts.update(config.method_options)
        if opts["latents"] is None:
            opts["latents"] = n_actions
        if opts["remap_max_steps"] is None and kind == "maze":
            n = abco_envs.maze_size(config.env)
            opts["remap_max_steps"] = 4 * n * n
        at_least = {"latents": 2, "train_steps": 0, "later_steps": 0, "hidden": 1, "channels": 1,
                    "pool": 1, "remap_steps": 0, "remap_envs": 1, "remap_epochs": 0}
        for key, low in at_least.items():
            value = opts[key]
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise ConfigError(f"ilpo option {key} must be an integer >= {low}, "
                                  f"got {value!r}")  # fmt: skip
        steps = opts["policy_steps"]
        if steps is not None and (not isinstance(steps, int) or isinstance(steps, bool)
                                  or steps < 1):  # fmt: skip
            raise ConfigError(f"ilpo option policy_steps must be null (train pi with G) or "
                              f"an integer >= 1, got {steps!r}")  # fmt: skip
        for key in ("exp_weight", "relax", "remap_epsilon", "split_noise"):
            if not isinstance(opts[key], (int, float)) or not 0.0 <= float(opts[key]) <= 1.0:
                raise ConfigError(f"ilpo option {key} must be in [0, 1], got {opts[key]!r}")
        if not 0.0 < float(opts["remap_margin"]) <= 1.0:
            raise ConfigError(f"ilpo option remap_margin must be in (0, 1], got "
                              f"{opts['remap_margin']!r}")  # fmt: skip
        if opts["remap_input"] not in _REMAP_INPUTS:
            raise ConfigError(f"ilpo option remap_input must be one of {_REMAP_INPUTS}, got "
                              f"{opts['remap_input']!r}")  # fmt: skip
        if opts["latent_init"] not in ("random", "shared"):
            raise ConfigError(f"ilpo option latent_init must be random or shared, got "
                              f"{opts['latent_init']!r}")  # fmt: skip
        if opts["target"] not in _TARGETS or (opts["target"] == "cells" and kind != "maze"):
            raise ConfigError(f"ilpo option target must be one of {_TARGETS} (cells: mazes "
                              f"only), got {opts['target']!r}")  # fmt: skip
        if opts["remap"] not in _REMAP_MODES:
            raise ConfigError(f"ilpo option remap must be one of {_REMAP_MODES}, got "
                              f"{opts['remap']!r}")  # fmt: skip
        return opts

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        super().__init__(config, data, rng)
        self.opts = opts = self.options(config, data.n_actions)
        self.k, self.n_actions = int(opts["latents"]), int(data.n_actions)
        self.device = torch.device(config.device)
        self.maze = data.is_maze
        shape = tuple(data.observation_space.shape)
        self.images = len(shape) == 3
        # -- the expert pairs and their targets (expert states only: ILPO uses no
        # pre-demonstrations and counts none) ---------------------------------------------------
        self.expert_obs = torch.from_numpy(data.expert_obs)
        self.expert_t = torch.from_numpy(data.expert_t)
        hidden = int(opts["hidden"])
        if self.images:
            self.pool = int(opts["pool"])
            self.cells = (CellAverage(abco_envs.maze_size(config.env), *shape[:2], total=True)
                          if opts["target"] == "cells" else None)  # fmt: skip
            pooled = self._pooled_delta(self.expert_obs[self.expert_t],
                                        self.expert_obs[self.expert_t + 1])  # fmt: skip
            self.delta_scale = float(pooled.pow(2).mean().sqrt().clamp_min(1e-8))
            self.expert_targets = pooled / self.delta_scale
            forward_model: nn.Module = ImageForwardModel(
                shape, self.k, self.pool, int(opts["channels"]),
                None if self.cells is None else self.cells.grid)
            policy = latent_policy(shape, self.k, hidden)
        else:
            states = data.expert_obs.astype(np.float64)
            deltas = states[data.expert_t + 1] - states[data.expert_t]
            self.delta_mean = torch.as_tensor(deltas.mean(0), dtype=torch.float32)
            self.delta_std = torch.as_tensor(np.maximum(deltas.std(0), 1e-8), dtype=torch.float32)
            mean, std = states.mean(0), np.maximum(states.std(0), 1e-8)
            forward_model = VectorForwardModel(shape[0], self.k, hidden, mean, std)
            policy = latent_policy(shape, self.k, hidden, mean, std)
            self.expert_targets = self._targets(self.expert_obs[self.expert_t],
                                                self.expert_obs[self.expert_t + 1])  # fmt: skip
        if opts["latent_init"] == "shared":  # one embedding, nudged apart (module docstring)
            with torch.no_grad():
                latent = forward_model.latent
                latent.copy_(latent[:1] + float(opts["split_noise"]) * torch.randn(latent.shape))
        self.net = ILPONet(forward_model, policy).to(self.device)
        self.opt = torch.optim.Adam(self.net.parameters(), lr=config.lr)
        remap_in = self.k
        remap_in += forward_model.embedding_features if "embedding" in opts["remap_input"] else 0
        remap_in += forward_model.out_features if "effect" in opts["remap_input"] else 0
        self.remap_net = RemapNet(remap_in, self.n_actions).to(self.device)
        self.remap_opt = torch.optim.Adam(self.remap_net.parameters(), lr=config.lr)
        # -- the remapping steps so far: (s, z*, a) of the steps some latent explains ------------
        self.remap_obs = torch.zeros((0, *shape), dtype=self.expert_obs.dtype)
        self.remap_z = torch.zeros(0, dtype=torch.long)
        self.remap_actions = torch.zeros(0, dtype=torch.long)
        self.remap_counts = np.zeros((self.k, self.n_actions), dtype=np.int64)
        self.remap_phases = 0
        self.labels: np.ndarray | None = None

    # -- targets ------------------------------------------------------------------------------

    def _pooled_delta(self, s: torch.Tensor, s1: torch.Tensor, chunk: int = 1024) -> torch.Tensor:
        """``avgpool(s' - s)`` of frames, flattened (``(B, C * H/p * W/p)``, CPU float32),
        or with ``target="cells"`` the sum of ``|s' - s|`` over each maze cell (``(B, n n)``)."""
        out = []
        for start in range(0, len(s), chunk):
            a = s[start : start + chunk].float().div_(255.0)
            b = s1[start : start + chunk].float().div_(255.0)
            d = (b - a).permute(0, 3, 1, 2)
            if self.cells is not None:  # how much each cell changed, whatever its colours
                d = self.cells(d.abs().sum(1, keepdim=True))
            elif self.pool > 1:
                d = F.avg_pool2d(d, self.pool)
            out.append(d.flatten(1))
        return torch.cat(out) if out else torch.zeros(0)

    def _targets(self, s: torch.Tensor, s1: torch.Tensor) -> torch.Tensor:
        """What ``G`` predicts for transitions ``s -> s'`` (CPU float32, ``(B, D)``)."""
        if self.images:
            return self._pooled_delta(s, s1) / self.delta_scale
        return ((s1.double() - s.double()).float() - self.delta_mean) / self.delta_std

    # -- training of E, G and pi on the expert pairs --------------------------------------------

    def _batches(self, n: int, steps: int, batch_size: int) -> Any:
        """``steps`` minibatches of ``range(n)``: shuffled epochs, one after another."""
        done = 0
        while done < steps:
            order = torch.from_numpy(self.rng.permutation(n))
            for start in range(0, n, batch_size):
                if done == steps:
                    return
                done += 1
                yield order[start : start + batch_size]

    def _train_latent_model(self, steps: int, policy_steps: int | None = None
                            ) -> dict[str, float]:  # fmt: skip
        """``steps`` Adam steps of ``L_min + L_exp`` on minibatches of the expert pairs, or
        (``policy_steps`` not ``None``) ``steps`` of ``L_min`` then ``policy_steps`` of
        ``L_exp`` against the fixed ``G``; the mean losses of the last (up to) 100 steps."""
        if policy_steps is not None:
            return self._train_in_turn(steps, policy_steps)
        w, relax = float(self.opts["exp_weight"]), float(self.opts["relax"])
        self.net.train()
        recent: list[tuple[float, float]] = []
        for idx in self._batches(len(self.expert_t), steps, self.config.batch_size):
            obs = self.expert_obs[self.expert_t[idx]].to(self.device)
            target = self.expert_targets[idx].to(self.device)
            _, pred, logits = self.net(obs)
            loss_min, _ = min_over_latents_loss(pred, target, relax)
            loss_exp = expected_prediction_loss(logits.softmax(1), pred, target, w)
            self.opt.zero_grad(set_to_none=True)
            (loss_min + loss_exp).backward()
            self.opt.step()
            recent = [*recent[-99:], (loss_min.item(), loss_exp.item())]
        mean = np.mean(recent, axis=0) if recent else (float("nan"), float("nan"))
        return {"loss_min": float(mean[0]), "loss_exp": float(mean[1]), "train_steps": steps}

    def _train_in_turn(self, steps: int, policy_steps: int) -> dict[str, float]:
        """``G`` alone for ``steps`` steps of ``L_min``, then ``pi`` alone for
        ``policy_steps`` steps of ``L_exp`` against the trained ``G`` (option
        ``policy_steps``). One Adam optimiser: parameters without a gradient are skipped."""
        relax = float(self.opts["relax"])
        model, policy = self.net.forward_model, self.net.policy
        self.net.train()
        recent_min: list[float] = []
        for idx in self._batches(len(self.expert_t), steps, self.config.batch_size):
            obs = self.expert_obs[self.expert_t[idx]].to(self.device)
            _, pred = model(obs)
            loss_min, _ = min_over_latents_loss(pred, self.expert_targets[idx].to(self.device),
                                                relax)  # fmt: skip
            self.opt.zero_grad(set_to_none=True)
            loss_min.backward()
            self.opt.step()
            recent_min = [*recent_min[-99:], loss_min.item()]
        recent_exp: list[float] = []
        for idx in self._batches(len(self.expert_t), policy_steps, self.config.batch_size):
            obs = self.expert_obs[self.expert_t[idx]].to(self.device)
            with torch.no_grad():
                _, pred = model(obs)
            target = self.expert_targets[idx].to(self.device)
            loss_exp = expected_prediction_loss(policy(obs).softmax(1), pred, target)
            self.opt.zero_grad(set_to_none=True)
            loss_exp.backward()
            self.opt.step()
            recent_exp = [*recent_exp[-99:], loss_exp.item()]
        return {"loss_min": float(np.mean(recent_min)) if recent_min else float("nan"),
                "loss_exp": float(np.mean(recent_exp)) if recent_exp else float("nan"),
                "train_steps": steps, "policy_steps": policy_steps}  # fmt: skip

    @torch.no_grad()
    def _latents_of(self, s: torch.Tensor, s1: torch.Tensor, batch: int = 512
                    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # fmt: skip
        """For transitions ``s -> s'``: ``z*``, the ratio of the best to the second-best
        latent's error, and ``argmax_z pi(z | s)`` (CPU tensors)."""
        self.net.eval()
        best, ratio, chosen = [], [], []
        for start in range(0, len(s), batch):
            a, b = s[start : start + batch], s1[start : start + batch]
            target = self._targets(a, b).to(self.device)
            _, pred, logits = self.net(a.to(self.device))
            errors = latent_errors(pred, target)
            two = errors.topk(2, dim=1, largest=False).values
            best.append(errors.argmin(1).cpu())
            ratio.append((two[:, 0] / two[:, 1].clamp_min(1e-12)).cpu())
            chosen.append(logits.argmax(1).cpu())
        if not best:
            empty = torch.zeros(0, dtype=torch.long)
            return empty, torch.zeros(0), empty
        return torch.cat(best), torch.cat(ratio), torch.cat(chosen)

    # -- the action remapping -------------------------------------------------------------------

    @torch.no_grad()
    def _remap_input(self, obs: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
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
        mode = self.opts["remap_input"]
        parts = [F.one_hot(z, self.k).to(h.dtype)]
        if mode in ("embedding", "effect+embedding"):
            parts.append(h)
        if mode in ("effect", "effect+embedding"):
            rows = torch.arange(len(z), device=z.device)
            parts.append(pred[rows, z] - pred.mean(1))
        return torch.cat(parts, dim=1)

    @torch.no_grad()
    def _remap(self, obs: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """``argmax_a P(a | s, z)`` (``obs`` and ``z`` on the device)."""
        if self.opts["remap"] == "table":
            table = torch.as_tensor(self.remap_counts, device=z.device)
            return table[z].argmax(1)
        self.remap_net.eval()
        return self.remap_net(self._remap_input(obs, z)).argmax(1)

    def _collect(self, epsilon: float) -> dict[str, float]:
        """``remap_steps`` environment steps (rounded up to whole steps of all ``remap_envs``
        slots), epsilon-greedy; keep ``(s, z*, a)`` of the steps a latent explains (module
        docstring); count every step as ``remapping``."""
        opts, data = self.opts, self.data
        slots = int(opts["remap_envs"])
        kwargs, options = dict(data.env_kwargs), None
        if self.maze:
            n = abco_envs.maze_size(self.config.env)
            layouts = len(abco_envs.layout_pool(n).split("train"))
            kwargs.update(split="train", max_episode_steps=int(opts["remap_max_steps"]))
            first = self.remap_phases * slots
            options = {"layout_index": [(first + i) % layouts for i in range(slots)],
                       "start": np.zeros((slots, 2), dtype=int)}  # fmt: skip
        envs = make_vector_env(self.config.env, slots, kwargs)
        obs, _ = envs.reset(seed=int(self.rng.integers(0, 2**31 - slots)), options=options)
        resetting = np.zeros(slots, dtype=bool)  # next-step autoreset: that step is no move
        s_rows, s1_rows, a_rows = [], [], []
        for _ in range(math.ceil(int(opts["remap_steps"]) / slots)):
            explore = self.rng.random(slots) < epsilon
            random_actions = self.rng.integers(0, self.n_actions, slots)
            actions = random_actions if explore.all() else np.where(
                explore, random_actions, self.act(obs))  # fmt: skip
            next_obs, _, terminated, truncated, _ = envs.step(actions)
            moved = ~resetting
            s_rows.append(obs[moved])
            s1_rows.append(next_obs[moved])
            a_rows.append(actions[moved])
            resetting = terminated | truncated
            obs = next_obs
        envs.close()
        s, s1 = torch.from_numpy(np.concatenate(s_rows)), torch.from_numpy(np.concatenate(s1_rows))
        actions = torch.from_numpy(np.concatenate(a_rows).astype(np.int64))
        self.count("remapping", len(actions))
        self.remap_phases += 1
        z, ratio, _ = self._latents_of(s, s1)
        keep = ratio < float(opts["remap_margin"])
        self.remap_obs = torch.cat([self.remap_obs, s[keep]])
        self.remap_z = torch.cat([self.remap_z, z[keep]])
        self.remap_actions = torch.cat([self.remap_actions, actions[keep]])
        np.add.at(self.remap_counts, (z[keep].numpy(), actions[keep].numpy()), 1)
        return {"remap_steps": int(len(actions)), "remap_kept": int(keep.sum()),
                "remap_epsilon": float(epsilon)}  # fmt: skip

    def _fit_remap(self) -> dict[str, float]:
        """Fit ``P(a | s, z)`` on every kept remapping step so far (``remap="state"``)."""
        n = len(self.remap_z)
        if self.opts["remap"] == "table" or n == 0:
            return {}
        self.remap_net.train()
        losses = []
        steps = int(self.opts["remap_epochs"]) * math.ceil(n / self.config.batch_size)
        for idx in self._batches(n, steps, self.config.batch_size):
            inputs = self._remap_input(self.remap_obs[idx].to(self.device),
                                       self.remap_z[idx].to(self.device))  # fmt: skip
            loss = F.cross_entropy(self.remap_net(inputs), self.remap_actions[idx].to(self.device))
            self.remap_opt.zero_grad(set_to_none=True)
            loss.backward()
            self.remap_opt.step()
            losses = [*losses[-19:], loss.item()]
        return {"remap_loss": float(np.mean(losses)) if losses else float("nan")}

    # -- one iteration ----------------------------------------------------------------------------

    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Iteration 0: train ``E, G, pi``; then (every iteration) remap with a step budget."""
        stats: dict[str, Any] = {}
        if iteration == 0:
            stats.update({f"option_{k}": v for k, v in self.opts.items()
                          if isinstance(v, (int, float)) and v is not None})  # fmt: skip
            steps = int(self.opts["train_steps"])
        else:
            steps = int(self.opts["later_steps"])
        policy_steps = self.opts["policy_steps"]
        if policy_steps is not None and iteration > 0:
            policy_steps = steps
        if steps:
            stats.update(self._train_latent_model(steps, policy_steps))
        epsilon = 1.0 if self.remap_phases == 0 else float(self.opts["remap_epsilon"])
        if int(self.opts["remap_steps"]) > 0:
            stats.update(self._collect(epsilon))
        stats.update(self._fit_remap())
        stats["remap_transitions"] = int(len(self.remap_z))
        stats.update(self._expert_statistics())
        return stats

    def _expert_statistics(self) -> dict[str, Any]:
        """Diagnostics on the expert's states (module docstring) and the inferred expert
        actions (``labels``, the remapped ``z*``). ``expert_label_accuracy`` scores those
        labels, ``policy_action_accuracy`` what :meth:`act` does (the remapped
        ``argmax_z pi``); the true actions are a measurement only, never a label."""
        s, s1 = self.expert_obs[self.expert_t], self.expert_obs[self.expert_t + 1]
        z, _, chosen = self._latents_of(s, s1)
        labels, acted = [], []
        for start in range(0, len(z), 512):
            obs = s[start : start + 512].to(self.device)
            labels.append(self._remap(obs, z[start : start + 512].to(self.device)).cpu())
            acted.append(self._remap(obs, chosen[start : start + 512].to(self.device)).cpu())
        empty = np.zeros(0, dtype=np.int64)
        self.labels = torch.cat(labels).numpy() if labels else empty
        actions = torch.cat(acted).numpy() if acted else empty
        truth = self.data.expert_eval_actions
        n = max(len(z), 1)
        return {
            "latent_usage": (np.bincount(z.numpy(), minlength=self.k) / n).tolist(),
            "policy_latent_usage": (np.bincount(chosen.numpy(), minlength=self.k) / n).tolist(),
            "policy_latent_agreement": float((chosen == z).float().mean()) if len(z) else 0.0,
            "expert_label_accuracy": float((self.labels == truth).mean()) if len(z) else 0.0,
            "policy_action_accuracy": float((actions == truth).mean()) if len(z) else 0.0,
        }  # fmt: skip

    # -- acting, labels, state -------------------------------------------------------------------

    @torch.no_grad()
    def act(self, obs: np.ndarray) -> np.ndarray:
        """``argmax_a P(a | s, z)`` with ``z = argmax_z pi(z | s)``, for a batch."""
        self.net.eval()
        x = torch.as_tensor(obs, device=self.device)
        z = self.net.policy(x).argmax(1)
        return self._remap(x, z).cpu().numpy()

    def expert_labels(self) -> np.ndarray | None:
        """The expert pairs' actions as ILPO infers them: the remapped ``z*`` of each pair."""
        return self.labels

    def state_dict(self) -> dict[str, Any]:
        """Networks, optimisers, the remapping steps kept so far, the generator's state."""
        return {
            "net": self.net.state_dict(), "opt": self.opt.state_dict(),
            "remap_net": self.remap_net.state_dict(), "remap_opt": self.remap_opt.state_dict(),
            "remap_obs": self.remap_obs, "remap_z": self.remap_z,
            "remap_actions": self.remap_actions, "remap_counts": self.remap_counts,
            "remap_phases": self.remap_phases, "labels": self.labels,
            "rng": self.rng.bit_generator.state,
        }  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict`."""
        self.net.load_state_dict(state["net"])
        self.opt.load_state_dict(state["opt"])
        self.remap_net.load_state_dict(state["remap_net"])
        self.remap_opt.load_state_dict(state["remap_opt"])
        for key in ("remap_obs", "remap_z", "remap_actions", "remap_counts", "remap_phases",
                    "labels"):  # fmt: skip
            setattr(self, key, state[key])
        self.rng.bit_generator.state = state["rng"]
