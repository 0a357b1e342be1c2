"""The BCO family's inverse dynamics model: its training set ``I_s``, its fitting with early
stopping on held-out pre-demonstrations, and its health measured after each fit.

:class:`IDMTraining` is a part of :class:`~abco_train.methods.bco.family.BCOFamily`, kept
apart so that each module reads on one screen or two: the family's algorithm (Algorithm 1)
there, the IDM's training here. It reads the family's data and networks (declared below).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from abco_train.config.run import RunConfig
from abco_train.harness.training_data import TrainingData
from abco_train.methods.bco.converged import Schedule, fit_converged
from abco_train.methods.bco.fitting import VALIDATION_CAP, fit, predict
from abco_train.methods.bco.health import MIN_JUDGED, at_chance
from abco_train.methods.bco.options import BCOOptions, resolved
from abco_train.networks.builders import build_networks

__all__ = ["IDMTraining"]


class IDMTraining:
    """The IDM's part of the BCO family (a mixin of :class:`BCOFamily`)."""

    config: RunConfig
    data: TrainingData
    options: BCOOptions
    schedule: Schedule | None
    rng: np.random.Generator
    device: torch.device
    augment: bool
    idm: torch.nn.Module
    idm_opt: torch.optim.Optimizer
    net_stats: dict[str, Any]
    chance: float
    pre_obs: Any
    pre_t: torch.Tensor
    pre_actions: torch.Tensor
    val_t: torch.Tensor
    val_actions: torch.Tensor
    pos_obs: torch.Tensor
    pos_t: torch.Tensor
    pos_actions: torch.Tensor
    s_pre: torch.Tensor
    s_pos: torch.Tensor

    @torch.no_grad()
    def validate_idm(self) -> dict[str, Any]:
        """Accuracy of the IDM on the held-out pre-demonstrations, overall and per class."""
        if len(self.val_t) == 0:
            return {"accuracy": float("nan"), "class_accuracy": []}
        pred = predict(self.idm, lambda idx: (self.pre_obs[self.val_t[idx]],
                                               self.pre_obs[self.val_t[idx] + 1]),
                        len(self.val_t), device=self.device)  # fmt: skip
        hits = (pred == self.val_actions).numpy()
        truth = self.val_actions.numpy()
        per_class = [float(hits[truth == c].mean()) if (truth == c).any() else float("nan")
                     for c in range(self.data.n_actions)]  # fmt: skip
        return {"accuracy": float(hits.mean()), "class_accuracy": per_class}

    def _train_idm_checked(self, max_epochs: int) -> dict[str, Any]:
        """Train the IDM with early stopping and measure its health, which never stops the
        run (:mod:`abco_train.methods.bco.health`); with ``idm_reinit`` an IDM at chance is
        re-initialised and trained once more."""
        loss, epochs = self._train_idm(max_epochs)
        health, reinitialised = self.validate_idm(), 0
        if self.options.idm_reinit and self._at_chance(health):
            self._new_idm()  # fresh weights from the run's torch generator, then once more
            loss, epochs = self._train_idm(max_epochs)
            health, reinitialised = self.validate_idm(), 1
        count = "idm_updates" if self.schedule is not None else "idm_epochs"
        return {"idm_loss": loss, count: epochs, "idm_val_accuracy": health["accuracy"],
                "idm_val_class_accuracy": health["class_accuracy"], "idm_chance": self.chance,
                "idm_at_chance": self._at_chance(health), "idm_reinitialised": reinitialised,
                "idm_train_accuracy": self._train_accuracy()}  # fmt: skip

    def _at_chance(self, health: dict[str, Any]) -> bool:
        return at_chance(health["accuracy"], self.chance, len(self.val_t), MIN_JUDGED)

    @torch.no_grad()
    def _train_accuracy(self) -> float:
        """The IDM's accuracy on its own ``I_s`` (``VALIDATION_CAP`` evenly spaced transitions
        at most): one fitting the policy's runs may be at chance on random actions only."""
        n = len(self.s_pre) + len(self.s_pos)
        if n == 0:
            return float("nan")
        rows = torch.linspace(0, n - 1, min(n, VALIDATION_CAP)).long()
        pairs, labels = self._idm_set()
        pred = predict(self.idm, lambda idx: pairs(rows[idx]), len(rows), device=self.device)
        return float((pred == labels[rows]).float().mean())

    def _new_idm(self) -> None:
        _, idm = build_networks(self.data.observation_space, self.data.n_actions,
                                self.config.arch, bool(self.config.attention),
                                resolved(self.options.idm_input), **self.net_stats)  # fmt: skip
        self.idm = idm.to(self.device)
        self.idm_opt = torch.optim.Adam(self.idm.parameters(), lr=resolved(self.config.lr))

    def _train_idm(self, max_epochs: int) -> tuple[float, int]:
        """Epochs of the IDM over ``I_s = I_pre[s_pre] + I_pos[s_pos]`` until the held-out
        accuracy stops improving (``idm_patience``) or ``max_epochs``; the best weights are
        kept. Returns the last epoch's mean loss and the epochs run (converged schedule:
        :func:`~abco_train.methods.bco.converged.fit_converged`, the updates made)."""
        if self.schedule is not None:
            pairs, labels = self._idm_set()
            out = fit_converged(self.idm, self.idm_opt, pairs, labels,
                                lambda: self.validate_idm()["accuracy"], self.schedule,
                                resolved(self.config.batch_size), self.rng, desc="IDM",
                                quiet=self.config.quiet, device=self.device,
                                augment=self.augment)  # fmt: skip
            return out["loss"], int(out["updates"])
        best, best_state, stale, loss, epochs = -1.0, None, 0, float("nan"), 0
        for epoch in range(1, max_epochs + 1):
            epochs, loss = epoch, self._idm_epoch()
            accuracy = self.validate_idm()["accuracy"]
            if np.isnan(accuracy) or accuracy > best:
                best, stale = accuracy, 0
                best_state = {k: v.detach().clone() for k, v in self.idm.state_dict().items()}
            else:
                stale += 1
            if stale >= resolved(self.options.idm_patience):
                break
        if best_state is not None:
            self.idm.load_state_dict(best_state)
        return loss, epochs

    def _idm_epoch(self) -> float:
        """One cross-entropy epoch of the IDM over ``I_s = I_pre[s_pre] + I_pos[s_pos]``."""
        pairs, labels = self._idm_set()
        return fit(self.idm, self.idm_opt, pairs, labels, 1, resolved(self.config.batch_size),
                    self.rng, "IDM", self.config.quiet, self.device, self.augment)  # fmt: skip

    def _idm_set(self) -> tuple[Any, torch.Tensor]:
        """``I_s``: its minibatch function (indices -> ``(s, s')``) and its action labels."""
        n_pre = len(self.s_pre)
        labels = torch.cat([self.pre_actions[self.s_pre], self.pos_actions[self.s_pos]])

        def pairs(idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            if n_pre == len(labels):  # I_s from I_pre alone: one gather per frame
                rows = self.pre_t[self.s_pre[idx]]
                return self.pre_obs[rows], self.pre_obs[rows + 1]
            is_pre = idx < n_pre
            s = torch.empty((len(idx), *self.pre_obs.shape[1:]), dtype=self.pre_obs.dtype,
                            device=self.device)
            s1 = torch.empty_like(s)
            rows = self.pre_t[self.s_pre[idx[is_pre]]]
            s[is_pre], s1[is_pre] = self.pre_obs[rows], self.pre_obs[rows + 1]
            rows = self.pos_t[self.s_pos[idx[~is_pre] - n_pre]]
            s[~is_pre], s1[~is_pre] = self.pos_obs[rows], self.pos_obs[rows + 1]
            return s, s1

        return pairs, labels
