"""LAPO: Learning to Act without Actions (Schmidt and Jiang, ICLR 2024).

LAPO learns what the actions are from observations alone: a latent inverse dynamics model
infers a latent action from each transition, a forward model must predict the transition
from the state and that latent, and a vector-quantised bottleneck between them keeps the
latent from copying the next state, so it can only say what changed, the action's effect.
A policy then clones the expert in latent space, and a small decoder, learnt from a few
action-labelled transitions, turns latents into actions. Where each stage lives here (the
losses are those of the authors' code, ``stage1_idm.py``, ``stage2_bc.py``, ``lapo/models.py``):

* **Stage 1, latent IDM and forward model** (:meth:`LAPO._model_step`):
  ``z = IDM(s, s')``, ``q = VQ(z)`` (:class:`~abco_train.methods.lapo.networks.
  VectorQuantiser`: EMA codebooks, commitment loss, straight-through gradients), and

      L_1 = || f(s, q) - target(s, s') ||^2 + commitment * || z - sg(q) ||^2

  trained jointly (the forward model's gradient reaches the IDM through ``q``), gradients
  clipped at ``grad_clip``. Data: observations only: the expert's transitions and the
  pre-demonstrations' (their actions unread), half a minibatch each. The authors' IDM also
  reads the frame before ``s`` and their forward model predicts the next frame's pixels with a
  U-Net; here the IDM is the run's IDM network on ``(s, s')`` (every abco env is Markov in its
  observation) and the forward model predicts ``s' - s`` standardised, or a maze frame's
  pooled difference (:class:`~abco_train.methods.lapo.networks.ForwardModel`).
* **Stage 2, latent behaviour cloning** (:meth:`LAPO._policy_step`): ``pi(s)``, the run's
  policy network with ``latent_dim`` outputs, regresses the IDM's continuous (pre-quantisation)
  latent of each expert transition, ``|| pi(s) - sg(z) ||^2``, the IDM frozen.
* **Stage 3, decoding, offline** (:meth:`LAPO._fit_decoder`): an MLP decoder ``d(a | z)`` is
  fitted by cross-entropy (label smoothing) on the pre-demonstrations' IDM latents and true
  actions, the small action-labelled set of the paper's offline variant; the agent acts
  ``argmax_a d(a | pi(s))``. The paper's online variant (PPO fine-tuning) is not run: every
  method here gets the same data and no reinforcement-learning steps but GAIfO's, whose
  method needs them.

Schedule: iteration 0 runs stage 1 (``model_steps``) and the decoder; stage 2's
``policy_steps`` are spread evenly over ``rounds`` iterations, each then evaluated. With
``schedule="converged"`` (:mod:`abco_train.methods.converged`) a tenth of the expert's and of
the pre-demonstrations' transitions is held out, and each stage trains until its held-out
score stops improving instead: stage 1 its loss ``L_1`` on the held-out transitions of both,
the decoder its accuracy on the held-out pre-demonstrations, stage 2 (once per round) its
latent regression error on the held-out expert transitions.

Interactions: the pre-demonstration transitions it trains on (with a ``--budget``, the first
ones it pays for), nothing online.

Diagnostics: ``probe_accuracy``, a linear probe's held-out accuracy at telling the true action
of a pre-demonstration from its latent (:func:`~abco_train.methods.lapo.networks.
linear_probe_accuracy`; the authors probe with an MLP): whether stage 1 found the actions;
``codes_used``, the distinct code tuples the expert's transitions get; the losses.

Options: :class:`~abco_train.methods.lapo.options.LAPOOptions` (``--lapo-model-steps``, ...).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from abco_train.config.run import RunConfig
from abco_train.harness.training_data import TrainingData
from abco_train.methods.converged import LOSS_GAIN, converge, schedule_of, split_rows
from abco_train.methods.lapo.networks import (
    ForwardModel,
    VectorQuantiser,
    decoder,
    linear_probe_accuracy,
)
from abco_train.methods.lapo.options import LAPOOptions
from abco_train.methods.offline import (
    OfflineMethod,
    iteration_steps,
    offline_data,
    state_network,
    transition_network,
)
from abco_train.methods.registry import register

__all__ = ["LAPO", "LAPOOptions"]

#: The most transitions the probe and the decoder read latents of at once.
CHUNK = 1024
#: The held-out splits' own streams (:func:`~abco_train.methods.converged.held_out_split`).
EXPERT_TAG, PRE_TAG = 0x4C, 0x4D


@register("lapo")
class LAPO(OfflineMethod):
    """LAPO (see the module docstring): latent actions, latent cloning, a decoder."""

    Options = LAPOOptions
    options: LAPOOptions

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        super().__init__(config, data, rng)
        opts = self.options
        self.device = torch.device(config.device)
        self.data_t = offline_data(self, data, self.device)
        stats, width = self.data_t.stats, opts.latent_dim
        self.frames = len(data.observation_space.shape) == 3
        self.target_scale = self._target_scale()
        out = self._target(*self.data_t.expert_pairs(torch.arange(1))).shape[1]
        self.idm = transition_network(config, data, stats, width).to(self.device)
        self.vq = VectorQuantiser(opts.codebooks, opts.slots, opts.code_dim, opts.codes,
                                  opts.commitment, opts.ema_decay).to(self.device)  # fmt: skip
        encoder = state_network(config, data, stats, opts.hidden)
        self.fdm = ForwardModel(encoder, opts.hidden, width, opts.hidden, out).to(self.device)
        self.policy = state_network(config, data, stats, width).to(self.device)
        self.decoder = decoder(width, opts.hidden, data.n_actions).to(self.device)
        self.model_opt = torch.optim.Adam([*self.idm.parameters(), *self.fdm.parameters()],
                                          lr=opts.model_lr)  # fmt: skip
        self.policy_opt = torch.optim.Adam(self.policy.parameters(), lr=opts.policy_lr)
        self.decoder_opt = torch.optim.Adam(self.decoder.parameters())
        self.stats: dict[str, float] = {}
        self._expert_z: torch.Tensor | None = None  # stage 2's targets, once stage 1 is done
        # -- the rows each stage trains on, and those held out (converged schedule only) --
        self.schedule = schedule_of(opts)
        held = self.schedule is not None
        self.expert_rows, self.expert_held = split_rows(len(self.data_t.expert_t), config.seed,
                                                        EXPERT_TAG, held)  # fmt: skip
        self.pre_rows, self.pre_held = split_rows(len(self.data_t.pre_t), config.seed, PRE_TAG,
                                                  held)  # fmt: skip

    # -- the forward model's target -------------------------------------------------------------

    def _raw_target(self, s: torch.Tensor, s1: torch.Tensor) -> torch.Tensor:
        """``s' - s`` (vectors) or its ``pool``-averaged difference image in ``[-1, 1]``."""
        if not self.frames:
            return s1.float() - s.float()
        d = (s1.float() - s.float()).div_(255.0).permute(0, 3, 1, 2)
        if self.options.pool > 1:
            d = F.avg_pool2d(d, self.options.pool)
        return d.flatten(1)

    @torch.no_grad()
    def _target_scale(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and std of the target over the pre-demonstrations (frames: zero and the RMS)."""
        n = len(self.data_t.pre_t)
        rows = torch.linspace(0, n - 1, min(n, 4 * CHUNK)).long()
        raw = self._raw_target(*self.data_t.pre_pairs(rows))
        if self.frames:
            return torch.zeros(()), raw.pow(2).mean().sqrt().clamp_min(1e-8)
        return raw.mean(0), raw.std(0).clamp_min(1e-6)

    def _target(self, s: torch.Tensor, s1: torch.Tensor) -> torch.Tensor:
        mean, std = self.target_scale
        return (self._raw_target(s, s1) - mean) / std

    # -- stage 1: latent IDM and forward model ----------------------------------------------------

    def _model_step(self, batch: int) -> tuple[float, float]:
        """One Adam step of ``L_1`` on half expert, half pre-demonstration transitions."""
        half = max(1, batch // 2)
        e = self.expert_rows[self.rng.integers(0, len(self.expert_rows), half)]
        p = self.pre_rows[self.rng.integers(0, len(self.pre_rows), batch - half)]
        prediction, commitment = self._model_losses(e, p)
        loss = prediction + commitment
        self.model_opt.zero_grad(set_to_none=True)
        loss.backward()
        params = [*self.idm.parameters(), *self.fdm.parameters()]
        torch.nn.utils.clip_grad_norm_(params, self.options.grad_clip)
        self.model_opt.step()
        return float(prediction.detach()), float(commitment.detach())

    def _model_losses(self, e: torch.Tensor, p: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``L_1``'s two terms on expert transitions ``e`` and pre-demonstrations ``p``."""
        (es, es1), (ps, ps1) = self.data_t.expert_pairs(e), self.data_t.pre_pairs(p)
        s, s1 = torch.cat([es, ps]), torch.cat([es1, ps1])
        q, commitment, _ = self.vq(self.idm(s, s1))
        return F.mse_loss(self.fdm(s, q), self._target(s, s1)), commitment

    @torch.no_grad()
    def _model_score(self) -> float:
        """Minus ``L_1`` on the held-out transitions (the codebooks left as they are)."""
        for net in (self.idm, self.fdm, self.vq):
            net.eval()
        e, p = self.expert_held, self.pre_held
        total, n = 0.0, 0
        for i in range(0, max(len(e), len(p)), CHUNK):
            ei, pi = e[i : i + CHUNK], p[i : i + CHUNK]
            prediction, commitment = self._model_losses(ei, pi)
            size = len(ei) + len(pi)
            total, n = total + float(prediction + commitment) * size, n + size
        for net in (self.idm, self.fdm, self.vq):
            net.train()
        return -total / n if n else float("nan")

    def _fit_model(self, batch: int) -> dict[str, float]:
        """Stage 1: ``model_steps`` steps, or (converged) until its held-out score stops
        improving; the mean losses of the last (up to) 100 steps."""
        self._expert_z = None
        for net in (self.idm, self.fdm, self.vq):
            net.train()
        losses: list[tuple[float, float]] = []

        def window(n: int) -> float:
            losses.extend(self._model_step(batch) for _ in range(n))
            del losses[:-100]
            return losses[-1][0] if losses else float("nan")

        steps = {"model_steps": float(self.options.model_steps)}
        if self.schedule is None:
            window(self.options.model_steps)
        else:
            out = converge(window, self._model_score, [self.idm, self.fdm, self.vq],
                           self.schedule, LOSS_GAIN)  # fmt: skip
            steps = {"model_steps": out["updates"], "model_held_out": out["best"]}
        self.vq.eval()
        tail = losses or [(float("nan"), float("nan"))]
        return {"forward_loss": float(np.mean([x[0] for x in tail])),
                "commitment_loss": float(np.mean([x[1] for x in tail])), **steps}  # fmt: skip

    @torch.no_grad()
    def latents(self, pairs: Any, n: int) -> torch.Tensor:
        """The IDM's continuous latents of ``n`` transitions (``pairs(idx) -> (s, s')``)."""
        self.idm.eval()
        out = [self.idm(*pairs(torch.arange(i, min(i + CHUNK, n)))) for i in range(0, n, CHUNK)]
        return torch.cat(out) if out else torch.zeros(0, self.options.latent_dim)

    # -- stage 3: the decoder, and the probe ------------------------------------------------------

    def _fit_decoder(self) -> dict[str, float]:
        """``decoder_epochs`` of cross-entropy on the pre-demonstrations' latents, or
        (converged) minibatches of them until the held-out accuracy stops improving."""
        z = self.latents(self.data_t.pre_pairs, len(self.data_t.pre_t))
        actions = self.data_t.pre_actions.to(self.device)
        self.decoder.train()
        loss = torch.zeros(())

        def update(idx: torch.Tensor) -> None:
            nonlocal loss
            loss = F.cross_entropy(self.decoder(z[idx]), actions[idx],
                                   label_smoothing=self.options.label_smoothing)
            self.decoder_opt.zero_grad(set_to_none=True)
            loss.backward()
            self.decoder_opt.step()

        if self.schedule is None:
            for _ in range(self.options.decoder_epochs):
                order = torch.from_numpy(self.rng.permutation(len(z)))
                for i in range(0, len(z), 512):
                    update(order[i : i + 512])
            return {"decoder_loss": float(loss.detach())}
        rows, held = self.pre_rows.to(z.device), self.pre_held.to(z.device)

        def window(n: int) -> float:
            self.decoder.train()
            for _ in range(n):
                update(rows[torch.from_numpy(self.rng.integers(0, len(rows), 512))])
            return float(loss.detach())

        @torch.no_grad()
        def accuracy() -> float:
            self.decoder.eval()
            hits = (self.decoder(z[held]).argmax(1) == actions[held]).float()
            return float(hits.mean()) if len(held) else float("nan")

        out = converge(window, accuracy, [self.decoder], self.schedule)
        return {"decoder_loss": out["loss"], "decoder_updates": out["updates"],
                "decoder_held_out_accuracy": out["best"]}  # fmt: skip

    def _expert_latents(self) -> torch.Tensor:
        """``z`` of every expert transition, stage 2's targets: the IDM is frozen after stage
        1, so they are computed once (the same values, row by row, as per minibatch)."""
        if self._expert_z is None:
            with torch.no_grad():
                self._expert_z = self.latents(self.data_t.expert_pairs,
                                              len(self.data_t.expert_t))  # fmt: skip
        return self._expert_z

    def _policy_loss(self, rows: torch.Tensor) -> torch.Tensor:
        """``|| pi(s) - sg(z) ||^2`` on expert transitions ``rows``."""
        s = self.data_t.expert_obs[self.data_t.expert_t[rows]]
        return F.mse_loss(self.policy(s), self._expert_latents()[rows])

    def _policy_step(self, batch: int) -> float:
        """One Adam step of ``|| pi(s) - sg(z) ||^2`` on expert transitions."""
        loss = self._policy_loss(self.expert_rows[self.rng.integers(0, len(self.expert_rows),
                                                                    batch)])  # fmt: skip
        self.policy_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.policy_opt.step()
        return float(loss.detach())

    @torch.no_grad()
    def _policy_score(self) -> float:
        """Minus the latent regression error on the held-out expert transitions."""
        self.policy.eval()
        held = self.expert_held
        total = sum(float(self._policy_loss(held[i : i + CHUNK])) * len(held[i : i + CHUNK])
                    for i in range(0, len(held), CHUNK))  # fmt: skip
        self.policy.train()
        return -total / len(held) if len(held) else float("nan")

    def _fit_policy(self, iteration: int, batch: int) -> dict[str, float]:
        """Stage 2: this round's share of ``policy_steps``, or (converged) until the held-out
        error stops improving."""
        self.policy.train()
        losses: list[float] = []

        def window(n: int) -> float:
            losses.extend(self._policy_step(batch) for _ in range(n))
            del losses[:-100]
            return losses[-1] if losses else float("nan")

        if self.schedule is None:
            steps = iteration_steps(self.options.policy_steps, iteration, self.num_iterations)
            window(steps)
            out = {"policy_steps": steps}
        else:
            fitted = converge(window, self._policy_score, [self.policy], self.schedule,
                              LOSS_GAIN)  # fmt: skip
            out = {"policy_steps": fitted["updates"], "policy_held_out": fitted["best"]}
        return {"policy_loss": float(np.mean(losses)) if losses else float("nan"), **out}

    # -- the schedule -----------------------------------------------------------------------------

    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Stages 1 and 3 in iteration 0; this iteration's share of stage 2."""
        batch = int(self.config.batch_size or 1)
        if iteration == 0:
            self.stats = {**self._fit_model(batch), **self._fit_decoder(), **self.probe()}
        return {**self.stats, **self._fit_policy(iteration, batch), **self._expert_accuracy()}

    def probe(self) -> dict[str, float]:
        """The linear probe's held-out accuracy on the pre-demonstrations' latents (at most
        ``4 * CHUNK`` transitions, evenly spaced), and the code tuples the expert uses."""
        n = len(self.data_t.pre_t)
        rows = torch.linspace(0, n - 1, min(n, 4 * CHUNK)).long()
        z = self.latents(lambda idx: self.data_t.pre_pairs(rows[idx]), len(rows)).cpu()
        accuracy = linear_probe_accuracy(z, self.data_t.pre_actions[rows],
                                         self.data.n_actions, self.rng)  # fmt: skip
        expert = self.latents(self.data_t.expert_pairs, len(self.data_t.expert_t))
        _, _, codes = self.vq(expert) if len(expert) else (None, None, torch.zeros(0, 1))
        return {"probe_accuracy": accuracy,
                "codes_used": float(len(torch.unique(codes, dim=0)))}  # fmt: skip

    @torch.no_grad()
    def _expert_accuracy(self) -> dict[str, float]:
        """How often the acting policy takes the expert's action in the expert's states (a
        measurement only, never a label)."""
        truth = self.data.expert_eval_actions
        if len(truth) == 0:
            return {}
        rows = self.data_t.expert_t
        acted = np.concatenate([self._act(self.data_t.expert_obs[rows[i : i + CHUNK]])
                                for i in range(0, len(rows), CHUNK)])  # fmt: skip
        return {"policy_action_accuracy": float((acted == truth).mean())}

    @torch.no_grad()
    def _act(self, x: torch.Tensor) -> np.ndarray:
        self.policy.eval()
        self.decoder.eval()
        return self.decoder(self.policy(x.to(self.device))).argmax(1).cpu().numpy()

    def act(self, obs: np.ndarray) -> np.ndarray:
        """``argmax_a d(a | pi(s))`` for a batch."""
        return self._act(torch.as_tensor(obs))

    # -- state ------------------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Networks (the codebooks as the VQ's buffers), optimisers, the iteration-0
        statistics and the generator's state (data only)."""
        return {"idm": self.idm.state_dict(), "vq": self.vq.state_dict(),
                "fdm": self.fdm.state_dict(), "policy": self.policy.state_dict(),
                "decoder": self.decoder.state_dict(), "model_opt": self.model_opt.state_dict(),
                "policy_opt": self.policy_opt.state_dict(),
                "decoder_opt": self.decoder_opt.state_dict(), "stats": dict(self.stats),
                "rng": self.rng.bit_generator.state}  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict`.

        Raises:
            TypeError: Statistics that are not numbers by name.
        """
        stats = state["stats"]
        if not isinstance(stats, dict) or not all(isinstance(v, float) for v in stats.values()):
            raise TypeError("LAPO's statistics are not a dict of floats")
        for name in ("idm", "vq", "fdm", "policy", "decoder"):
            getattr(self, name).load_state_dict(state[name])
        self._expert_z = None  # the restored IDM's, when stage 2 next needs them
        for name in ("model_opt", "policy_opt", "decoder_opt"):
            getattr(self, name).load_state_dict(state[name])
        self.stats = dict(stats)
        self.rng.bit_generator.state = state["rng"]
