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
* **Action remapping** (Sec. 3.3; :mod:`abco_train.methods.ilpo.remapping`): the agent
  acts in the environment, ``a = argmax_a P(a | s, z)`` for ``z = argmax_z pi(z | s)``
  (:meth:`ILPO.act`), epsilon-greedy; for every step ``(s, a, s')`` it finds the latent that
  explains it, ``z* = argmin_z || Delta(s, s') - G(E(s), z) ||^2``, and fits ``P(a | s, z*)``
  by cross-entropy: a small classifier, as the authors' remapping network, reading (detached)
  ``onehot(z)``, ``E(s)`` and what ``z`` does in ``s``, ``G(E(s), z) - mean_z' G(E(s), z')``
  (``remap_input``; see :meth:`~abco_train.methods.ilpo.remapping.ActionRemapping.inputs`
  for why), or a count table ``P(a | z*)`` (``remap="table"``). Every such step is counted as
  a ``remapping`` interaction (:meth:`~abco_train.methods.base.Method.count`). A step that no
  latent explains clearly (the best latent's error is not below ``remap_margin`` times the
  second best's: an action the expert never took, or a move into a maze wall, which changes
  nothing) says nothing about the mapping and is left out of the fit (it is still counted);
  ``remap_margin`` is 0.1 for classic control, 0.5 for mazes.

What ``G`` predicts and with what networks (vector states, frames, maze cells), and why:
:mod:`abco_train.methods.ilpo.networks` (the targets are :meth:`ILPO._targets`).

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
``later_steps`` each), takes ``remap_steps`` more environment steps, epsilon-greedy
(``remap_epsilon``) with the current mapping, and refits the remapping on all the kept steps
so far (``remap_epochs`` epochs). The steps run in a vector env of ``remap_envs`` slots of
their own (:func:`abco_train.harness.rollouts.make_vector_env`, reset from the run's
generator; mazes: the train split's layouts from the start cell, cycling through them,
episodes cut after ``remap_max_steps``, default ``4 n^2``); the step after an episode ends is
the env's reset, not a transition, and is neither kept nor counted; with a ``--budget`` a
round takes at most the interactions left (none once it is spent). With ``schedule="converged"``
(:mod:`abco_train.methods.ilpo.training`) every fit of ``G`` and ``pi`` runs until its loss on a
held-out tenth of the expert's transitions stops improving instead of for its step counts;
the remapping keeps its epochs (its data arrive online, round by round). ILPO learns nothing
from the evaluation runs (no post-demonstrations) and uses no pre-demonstrations (it counts
none).

Diagnostics (``metrics.jsonl``, every iteration, on the expert's states):
``latent_usage`` (how often each latent is ``z*``), ``policy_latent_usage`` (how often each
latent is ``argmax_z pi``), ``policy_latent_agreement`` (``argmax_z pi = z*``),
``expert_label_accuracy`` (the inferred labels, the remapped ``z*`` that
:meth:`ILPO.expert_labels` returns, against the true actions: it measures ``G`` and the
remapping, not the policy) and ``policy_action_accuracy`` (what :meth:`ILPO.act`, the
evaluated policy, does in the expert's states against the expert's actions). The true
actions are a measurement only, never used for training or for a choice.

Options: :class:`~abco_train.methods.ilpo.options.ILPOOptions` (flags ``--ilpo-latents``,
``--ilpo-train-steps``, ..., or ``--method-options`` keys), each with its help text; their
defaults by env kind and by env, and why, are in :mod:`abco_train.methods.ilpo.options`. All
randomness comes from the run's generator and from torch (seeded by the harness): the same
seed gives the same run on CPU.

It is registered through :func:`abco_train.methods.registry.register` like any plugin. The
losses and networks are in :mod:`abco_train.methods.ilpo.networks` (imported here under the
same names), the remapping in :mod:`abco_train.methods.ilpo.remapping`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

import abco_envs
from abco_data.torch_view import frames_tensor
from abco_train.config.run import RunConfig
from abco_train.harness.training_data import TrainingData
from abco_train.methods.base import Method
from abco_train.methods.converged import schedule_of, split_rows
from abco_train.methods.ilpo.networks import (
    ILPONet,
    ImageForwardModel,
    VectorForwardModel,
    expected_prediction_loss,
    latent_errors,
    latent_policy,
    min_over_latents_loss,
)
from abco_train.methods.ilpo.options import ENV_OPTION_DEFAULTS, OPTION_DEFAULTS, ILPOOptions
from abco_train.methods.ilpo.remapping import ActionRemapping, remapping_steps
from abco_train.methods.ilpo.training import HELD_OUT_TAG, LatentTraining
from abco_train.methods.registry import register
from abco_train.networks.cells import CellAverage

__all__ = ["ILPO", "ILPOOptions", "CellAverage", "ILPONet", "VectorForwardModel",
           "ImageForwardModel", "latent_policy", "min_over_latents_loss",
           "expected_prediction_loss", "latent_errors", "OPTION_DEFAULTS",
           "ENV_OPTION_DEFAULTS"]  # fmt: skip


@register("ilpo")
class ILPO(LatentTraining, Method):
    """ILPO (see the module docstring): latent forward model and policy, then remapping."""

    Options = ILPOOptions
    options: ILPOOptions

    @classmethod
    def fixed(cls, name: str) -> Mapping[str, Any]:
        """No self-attention: ILPO's networks have none (its paper's are plain), so its record
        says so, whatever ``--attention`` says, and an older record that said otherwise is
        the same run."""
        return {"attention": False}

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        super().__init__(config, data, rng)
        opts = self.options
        self.k, self.n_actions = int(opts.latents or 0), int(data.n_actions)
        self.device = torch.device(config.device)
        self.maze = data.is_maze
        shape = tuple(data.observation_space.shape)
        self.images = len(shape) == 3
        # -- the expert pairs and their targets (expert states only: ILPO uses no
        # pre-demonstrations and counts none) ---------------------------------------------------
        self.expert_obs = frames_tensor(data.expert_obs)
        self.expert_t = torch.from_numpy(data.expert_t)
        hidden = int(opts.hidden)
        if self.images:
            self.pool = int(opts.pool)
            self.cells = (CellAverage(abco_envs.maze_size(config.env), *shape[:2], total=True)
                          if opts.target == "cells" else None)  # fmt: skip
            pooled = self._pooled_delta(self.expert_obs[self.expert_t],
                                        self.expert_obs[self.expert_t + 1])  # fmt: skip
            self.delta_scale = float(pooled.pow(2).mean().sqrt().clamp_min(1e-8))
            self.expert_targets = pooled / self.delta_scale
            forward_model: nn.Module = ImageForwardModel(
                shape, self.k, self.pool, int(opts.channels),
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
        if opts.latent_init == "shared":  # one embedding, nudged apart (module docstring)
            with torch.no_grad():
                latent = forward_model.latent
                latent.copy_(latent[:1] + float(opts.split_noise) * torch.randn(latent.shape))
        self.net = ILPONet(forward_model, policy).to(self.device)
        lr = config.lr
        assert lr is not None, "the run's config is resolved before its method is built"
        self.opt = torch.optim.Adam(self.net.parameters(), lr=lr)
        #: ``P(a | s, z)`` and the remapping steps so far: (s, z*, a) of the steps some latent
        #: explains.
        self.remapping = ActionRemapping(self.net, self.n_actions, opts, shape,
                                         self.expert_obs.dtype, self.device, lr)  # fmt: skip
        self.labels: np.ndarray | None = None
        # -- the expert transitions G and pi train on, and those held out (converged) ------
        self.schedule = schedule_of(opts)
        self.train_rows, self.held_rows = split_rows(len(self.expert_t), config.seed,
                                                     HELD_OUT_TAG, self.schedule is not None)

    # -- targets ------------------------------------------------------------------------------

    def _pooled_delta(self, s: torch.Tensor, s1: torch.Tensor, chunk: int = 1024) -> torch.Tensor:
        """``avgpool(s' - s)`` of frames, flattened (``(B, C * H/p * W/p)``, CPU float32),
        or with ``target="cells"`` the sum of ``|s' - s|`` over each maze cell (``(B, n n)``)."""
        out, cells = [], self.cells
        for start in range(0, len(s), chunk):
            a = s[start : start + chunk].float().div_(255.0)
            b = s1[start : start + chunk].float().div_(255.0)
            d = (b - a).permute(0, 3, 1, 2)
            if cells is not None:  # how much each cell changed, whatever its colours
                d = cells(d.abs().sum(1, keepdim=True))
            elif self.pool > 1:
                d = F.avg_pool2d(d, self.pool)
            out.append(d.flatten(1))
        return torch.cat(out) if out else torch.zeros(0)

    def _targets(self, s: torch.Tensor, s1: torch.Tensor) -> torch.Tensor:
        """What ``G`` predicts for transitions ``s -> s'`` (CPU float32, ``(B, D)``)."""
        if self.images:
            return self._pooled_delta(s, s1) / self.delta_scale
        return ((s1.double() - s.double()).float() - self.delta_mean) / self.delta_std

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

    # -- one iteration ----------------------------------------------------------------------------

    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Iteration 0: train ``E, G, pi``; then (every iteration) remap with a step budget."""
        opts, stats = self.options, dict[str, Any]()
        if iteration == 0:
            stats.update({f"option_{k}": v for k, v in opts.to_dict().items()
                          if isinstance(v, (int, float)) and v is not None})  # fmt: skip
            steps = int(opts.train_steps)
        else:
            steps = int(opts.later_steps)
        policy_steps = opts.policy_steps
        if policy_steps is not None and iteration > 0:
            policy_steps = steps
        if steps:
            stats.update(self._train_latent_model(steps, policy_steps))
        epsilon = 1.0 if self.remapping.phases == 0 else float(opts.remap_epsilon)
        if int(opts.remap_steps) > 0 and self.budget_left != 0:  # none: the budget is spent
            stats.update(self._collect(epsilon))
        stats.update(self.remapping.fit(int(opts.remap_epochs), self._batch_size, self.rng))
        stats["remap_transitions"] = int(len(self.remapping.z))
        stats.update(self._expert_statistics())
        return stats

    def _collect(self, epsilon: float) -> dict[str, float]:
        """One round of remapping steps (:func:`remapping_steps`, at most the budget left),
        every one counted as ``remapping``; keep ``(s, z*, a)`` of the steps a latent explains
        (module docstring)."""
        s, s1, actions = remapping_steps(self.config, self.data, self.options,
                                         self.remapping.phases, self.rng, self.act,
                                         epsilon, self.budget_left)  # fmt: skip
        self.count("remapping", len(actions))
        self.remapping.phases += 1
        z, ratio, _ = self._latents_of(s, s1)
        keep = ratio < float(self.options.remap_margin)
        self.remapping.keep(s[keep], z[keep], actions[keep])
        return {"remap_steps": int(len(actions)), "remap_kept": int(keep.sum()),
                "remap_epsilon": float(epsilon)}  # fmt: skip

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
            labels.append(self.remapping.action(obs, z[start : start + 512].to(self.device)).cpu())
            acted.append(self.remapping.action(obs, chosen[start : start + 512].to(self.device))
                         .cpu())  # fmt: skip
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
        return self.remapping.action(x, z).cpu().numpy()

    def expert_labels(self) -> np.ndarray | None:
        """The expert pairs' actions as ILPO infers them: the remapped ``z*`` of each pair."""
        return self.labels

    def state_dict(self) -> dict[str, Any]:
        """Networks, optimisers, the remapping steps kept so far, the generator's state (data:
        tensors, numpy arrays, ints)."""
        return {"net": self.net.state_dict(), "opt": self.opt.state_dict(),
                **self.remapping.state_dict(), "labels": self.labels,
                "rng": self.rng.bit_generator.state}  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict`.

        Raises:
            TypeError: Labels or remapping steps that are not the arrays it stores.
        """
        if not isinstance(state["labels"], np.ndarray):
            raise TypeError(f"labels are a {type(state['labels']).__name__}, not an array")
        self.net.load_state_dict(state["net"])
        self.opt.load_state_dict(state["opt"])
        self.remapping.load_state_dict(state)
        self.labels = state["labels"]
        self.rng.bit_generator.state = state["rng"]
