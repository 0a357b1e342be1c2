"""ILPO's training of ``E``, ``G`` and ``pi`` on the expert pairs (:class:`LatentTraining`, a
mixin of :class:`~abco_train.methods.ilpo.method.ILPO`): jointly (``L_min + L_exp``) or in turn
(``G`` on ``L_min``, then ``pi`` on ``L_exp`` against the fixed ``G``), for step counts or, with
``schedule="converged"`` (:mod:`abco_train.methods.converged`), until the held-out loss stops
improving. The converged schedule holds out a tenth of the expert's transitions (a stream of
its own); a fit is scored by its losses on them: the joint fit by ``L_min + L_exp``, ``G`` by
``L_min``, ``pi`` by ``L_exp``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from abco_train.config.run import RunConfig
from abco_train.methods.converged import LOSS_GAIN, Schedule, converge
from abco_train.methods.ilpo.networks import (
    ILPONet,
    expected_prediction_loss,
    min_over_latents_loss,
    minibatches,
)

__all__ = ["LatentTraining", "HELD_OUT_TAG"]

#: The held-out expert split's own stream (:func:`~abco_train.methods.converged.held_out_split`).
HELD_OUT_TAG = 0x1B
#: The most held-out transitions scored at once.
CHUNK = 512


class LatentTraining:
    """Fits of ILPO's latent model and latent policy (the attributes are ILPO's)."""

    config: RunConfig
    options: Any
    net: ILPONet
    opt: torch.optim.Optimizer
    rng: np.random.Generator
    device: torch.device
    expert_obs: Any
    expert_t: torch.Tensor
    expert_targets: torch.Tensor
    schedule: Schedule | None
    #: The expert transitions the fits train on, and those held out (converged only).
    train_rows: torch.Tensor
    held_rows: torch.Tensor

    @property
    def _batch_size(self) -> int:
        """The run's minibatch size (``None`` only in a config not yet resolved)."""
        batch_size = self.config.batch_size
        assert batch_size is not None, "the run's config is resolved before its method is built"
        return batch_size

    def _batches(self, steps: int) -> Any:
        """``steps`` minibatches of training rows: ``(obs, target)`` on the device."""
        for idx in minibatches(self.rng, len(self.train_rows), steps, self._batch_size):
            rows = self.train_rows[idx]
            yield (self.expert_obs[self.expert_t[rows]].to(self.device),
                   self.expert_targets[rows].to(self.device))  # fmt: skip

    def _fit(self, window: Callable[[int], float], steps: int, score: Callable[[], float],
             modules: list[torch.nn.Module]) -> float:  # fmt: skip
        """``steps`` updates, or (converged) windows until ``score`` stops improving; the
        updates made."""
        if self.schedule is None:
            window(steps)
            return float(steps)
        return converge(window, score, modules, self.schedule, LOSS_GAIN)["updates"]

    @torch.no_grad()
    def held_out_losses(self) -> tuple[float, float]:
        """``(L_min, L_exp)`` on the held-out expert transitions (NaN where none is held)."""
        self.net.eval()
        totals, n = np.zeros(2), len(self.held_rows)
        for start in range(0, n, CHUNK):
            rows = self.held_rows[start : start + CHUNK]
            obs = self.expert_obs[self.expert_t[rows]].to(self.device)
            target = self.expert_targets[rows].to(self.device)
            _, pred, logits = self.net(obs)
            loss_min, _ = min_over_latents_loss(pred, target, float(self.options.relax))
            loss_exp = expected_prediction_loss(logits.softmax(1), pred, target)
            totals += np.array([float(loss_min), float(loss_exp)]) * len(rows)
        self.net.train()
        return (float(totals[0] / n), float(totals[1] / n)) if n else (np.nan, np.nan)

    def _held_stats(self) -> dict[str, float]:
        """The held-out losses after a converged fit (none with step counts)."""
        if self.schedule is None:
            return {}
        loss_min, loss_exp = self.held_out_losses()
        return {"held_out_loss_min": loss_min, "held_out_loss_exp": loss_exp}

    def _train_latent_model(self, steps: int, policy_steps: int | None = None
                            ) -> dict[str, float]:  # fmt: skip
        """``steps`` Adam steps of ``L_min + L_exp`` on minibatches of the expert pairs, or
        (``policy_steps`` not ``None``) ``steps`` of ``L_min`` then ``policy_steps`` of
        ``L_exp`` against the fixed ``G``; the mean losses of the last (up to) 100 steps."""
        if policy_steps is not None:
            return self._train_in_turn(steps, policy_steps)
        w, relax = float(self.options.exp_weight), float(self.options.relax)
        self.net.train()
        recent: list[tuple[float, float]] = []

        def window(n: int) -> float:
            nonlocal recent
            for obs, target in self._batches(n):
                _, pred, logits = self.net(obs)
                loss_min, _ = min_over_latents_loss(pred, target, relax)
                loss_exp = expected_prediction_loss(logits.softmax(1), pred, target, w)
                self.opt.zero_grad(set_to_none=True)
                (loss_min + loss_exp).backward()
                self.opt.step()
                recent = [*recent[-99:], (loss_min.item(), loss_exp.item())]
            return sum(recent[-1]) if recent else float("nan")

        updates = self._fit(window, steps, lambda: -sum(self.held_out_losses()), [self.net])
        mean = np.mean(recent, axis=0) if recent else (float("nan"), float("nan"))
        return {"loss_min": float(mean[0]), "loss_exp": float(mean[1]),
                "train_steps": updates if self.schedule else steps, **self._held_stats()}

    def _train_in_turn(self, steps: int, policy_steps: int) -> dict[str, float]:
        """``G`` alone for ``steps`` steps of ``L_min``, then ``pi`` alone for
        ``policy_steps`` steps of ``L_exp`` against the trained ``G`` (option
        ``policy_steps``). One Adam optimiser: parameters without a gradient are skipped."""
        relax = float(self.options.relax)
        model, policy = self.net.forward_model, self.net.policy
        self.net.train()
        recent_min: list[float] = []
        recent_exp: list[float] = []

        def model_window(n: int) -> float:
            nonlocal recent_min
            for obs, target in self._batches(n):
                _, pred = model(obs)
                loss_min, _ = min_over_latents_loss(pred, target, relax)
                self.opt.zero_grad(set_to_none=True)
                loss_min.backward()
                self.opt.step()
                recent_min = [*recent_min[-99:], loss_min.item()]
            return recent_min[-1] if recent_min else float("nan")

        def policy_window(n: int) -> float:
            nonlocal recent_exp
            for obs, target in self._batches(n):
                with torch.no_grad():
                    _, pred = model(obs)
                loss_exp = expected_prediction_loss(policy(obs).softmax(1), pred, target)
                self.opt.zero_grad(set_to_none=True)
                loss_exp.backward()
                self.opt.step()
                recent_exp = [*recent_exp[-99:], loss_exp.item()]
            return recent_exp[-1] if recent_exp else float("nan")

        g_updates = self._fit(model_window, steps, lambda: -self.held_out_losses()[0], [model])
        pi_updates = self._fit(policy_window, policy_steps, lambda: -self.held_out_losses()[1],
                               [policy])  # fmt: skip
        converged = self.schedule is not None
        return {"loss_min": float(np.mean(recent_min)) if recent_min else float("nan"),
                "loss_exp": float(np.mean(recent_exp)) if recent_exp else float("nan"),
                "train_steps": g_updates if converged else steps,
                "policy_steps": pi_updates if converged else policy_steps,
                **self._held_stats()}  # fmt: skip
