"""DILO: Dual Imitation Learning from Observations (Sikchi, Chuck, Zhang, Niekum, 2024).

"A Dual Approach to Imitation Learning from Observations with Offline Datasets" (CoRL 2024).
DILO learns from the expert's states and an offline dataset of action-labelled transitions
of any quality (here: the pre-demonstrations), with no interaction. It matches the learner's
state-transition occupancy to the expert's through the dual of an f-divergence whose
Lagrange multiplier is a function of a transition, the *utility* ``V(s, s')``: an action-free
dual, so no inverse dynamics model and no discriminator stand between the expert's states and
the policy. Where each part of the method lives here (the exact losses are those of the
authors' code, ``DILO.update_full`` in ``dilo.py``: the paper's body could not be read here):

* **The dual** (:func:`dual_loss`): with ``d^E`` the expert's transitions, ``rho`` the
  offline ones and the residual ``delta(s, s', s'') = gamma V(s', s'') - V(s, s')``,

      L(V) = lam * E_{Mix_beta(d^E, rho)}[ f*(delta) ] - lam (1 - beta) E_rho[ delta ]
             + (1 - lam) E_rho[ V(s, s') ]

  with the chi-square (Pearson) conjugate ``f*(x) = x w - (w - 1)^2``, ``w = max(x / 2 + 1,
  0)`` (:func:`f_star`). The authors' code replaces the paper's initial-state term
  ``beta (1 - gamma) E_{d0}[V]`` with ``(1 - lam) E_rho[V]``; so does this one.
* **Orthogonal gradient** (ODICE): the residual is taken two ways, forward (the target
  network's ``V(s', s'')``, the online ``V(s, s')``) and backward (the online ``V(s', s'')``,
  the target's ``V(s, s')``); the update is ``g_f`` plus the part of ``eta g_b`` orthogonal to
  it (:func:`orthogonal_gradient`). The target follows ``V`` by Polyak averaging.
* **Policy extraction**: weighted behaviour cloning on the offline transitions with their
  true actions, ``-E_rho[ w(s, s') log pi(a | s) ]``, ``w = min(exp(tau V(s, s')), clip)``
  with ``V`` the smaller of the twin heads. The authors' policy is a deterministic tanh
  network with a squared error for continuous actions; for discrete actions the
  log-likelihood, the paper's own form, is the natural one (a categorical policy).

``V(s, s')`` is the run's IDM network with two outputs (the twin heads, one encoder: the
authors' twin has two); ``pi`` the run's policy network
(:mod:`abco_train.methods.offline`). Both train together, ``steps`` Adam steps spread evenly
over ``rounds`` iterations (each then evaluated), on minibatches of ``--batch-size``
offline and as many expert transitions. Transitions whose next state ends its episode have no
``s''`` and are left out of the dual (the authors' data loader drops them too); the policy
learns from all offline transitions.

Interactions: DILO counts the pre-demonstration transitions it trains on (with a
``--budget``, the first ones it pays for) and nothing online. Diagnostics per iteration:
the dual's loss, the mean weight of the expert's transitions and of the offline ones (and
their ratio: DILO should weigh expert-like transitions more), the share of the offline weight
mass on the transitions whose action the policy takes.

Options: :class:`~abco_train.methods.dilo.options.DILOOptions` (``--dilo-steps``, ...), the
authors' values but for the steps and learning rates.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.training_data import TrainingData
from abco_train.methods.converged import LOSS_GAIN, converge, schedule_of, split_rows
from abco_train.methods.dilo.options import DILOOptions
from abco_train.methods.offline import (
    OfflineMethod,
    iteration_steps,
    offline_data,
    state_network,
    transition_network,
    triples,
)
from abco_train.methods.registry import register

__all__ = ["DILO", "DILOOptions", "f_star", "dual_loss", "orthogonal_gradient"]

#: The most transitions the diagnostics read at once.
CHUNK = 1024
#: The held-out splits' own streams (:func:`~abco_train.methods.converged.held_out_split`).
PRE_TAG, EXPERT_TAG, POLICY_TAG = 0xD1, 0xD2, 0xD3


def f_star(x: torch.Tensor) -> torch.Tensor:
    """The Pearson chi-square conjugate of the authors' code: ``x w - (w - 1)^2`` with
    ``w = max(x / 2 + 1, 0)``, i.e. ``x + x^2 / 4`` for ``x >= -2`` and ``-1`` below.

    Example:
        >>> f_star(torch.tensor([-4.0, -2.0, 0.0, 2.0])).tolist()
        [-1.0, -1.0, 0.0, 3.0]
    """
    w = (x / 2 + 1).clamp_min(0)
    return x * w - (w - 1) ** 2


def dual_loss(expert_residual: torch.Tensor, offline_residual: torch.Tensor, beta: float
              ) -> torch.Tensor:  # fmt: skip
    """``E[beta f*(delta_E) + (1 - beta) f*(delta_rho) - (1 - beta) delta_rho]`` over a
    minibatch of each (the residual terms of DILO's dual, before ``lam``).

    Example:
        >>> dual_loss(torch.tensor([2.0]), torch.tensor([0.0]), 0.5).item()
        1.5
    """
    return (beta * f_star(expert_residual).mean() + (1 - beta) * f_star(offline_residual).mean()
            - (1 - beta) * offline_residual.mean())  # fmt: skip


def orthogonal_gradient(forward: list[torch.Tensor], backward: list[torch.Tensor]
                        ) -> list[torch.Tensor]:  # fmt: skip
    """``g_f + g_b - c g_f`` with ``c = <g_f, g_b> / |g_f|^2``: the forward gradient plus the
    part of the backward one orthogonal to it (ODICE's update, as DILO's code makes it).

    Example:
        >>> [g.tolist() for g in orthogonal_gradient([torch.tensor([1.0, 0.0])],
        ...                                          [torch.tensor([3.0, 2.0])])]
        [[1.0, 2.0]]
    """
    dot = sum((f * b).sum() for f, b in zip(forward, backward))
    norm = sum(f.pow(2).sum() for f in forward)
    c = dot / torch.clamp(torch.as_tensor(norm), min=1e-10)
    return [(1 - c) * f + b for f, b in zip(forward, backward)]


@register("dilo")
class DILO(OfflineMethod):
    """DILO (see the module docstring): the action-free dual, then weighted cloning."""

    Options = DILOOptions
    options: DILOOptions

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        super().__init__(config, data, rng)
        opts = self.options
        self.device = torch.device(config.device)
        self.data_t = offline_data(self, data, self.device)
        # the dual reads (s, s', s''): rows of s whose next transition is in the same episode
        pre_t, expert_t = self.data_t.pre_t.numpy(), self.data_t.expert_t.numpy()
        self.pre_rows = torch.from_numpy(pre_t[triples(pre_t)])
        self.expert_rows = torch.from_numpy(expert_t[triples(expert_t)])
        if len(self.pre_rows) == 0 or len(self.expert_rows) == 0:
            which = "pre-demonstrations" if len(self.pre_rows) == 0 else "expert data"
            raise ConfigError(f"dilo needs episodes of two transitions or more; the {which} "
                              "it trains on have none")  # fmt: skip
        stats = self.data_t.stats
        self.value = transition_network(config, data, stats, 2).to(self.device)  # twin heads
        # the target network: no gradient, always in evaluation mode (no dropout noise)
        self.target = copy.deepcopy(self.value).requires_grad_(False).eval()
        self.policy = state_network(config, data, stats, data.n_actions, actions=True
                                    ).to(self.device)  # fmt: skip
        assert opts.value_lr and opts.policy_lr, "the run's lr fills them once it is resolved"
        self.value_opt = torch.optim.Adam(self.value.parameters(), lr=opts.value_lr)
        self.policy_opt = torch.optim.Adam(self.policy.parameters(), lr=opts.policy_lr)
        # -- what trains and what is held out: positions in pre_rows, expert_rows, pre_t ----
        self.schedule = schedule_of(opts)
        held, seed = self.schedule is not None, config.seed
        self.pre_train, self.pre_held = split_rows(len(self.pre_rows), seed, PRE_TAG, held)
        self.expert_train, self.expert_held = split_rows(len(self.expert_rows), seed,
                                                         EXPERT_TAG, held)  # fmt: skip
        self.policy_train, self.policy_held = split_rows(len(self.data_t.pre_t), seed,
                                                         POLICY_TAG, held)  # fmt: skip

    # -- one update -------------------------------------------------------------------------------

    def _triples(self, pre_rows: torch.Tensor, expert_rows: torch.Tensor
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # fmt: skip
        """``(s, s', s'')`` of the offline triples then the expert's, one batch."""
        pre, expert = self.data_t.pre_obs, self.data_t.expert_obs
        return tuple(torch.cat([pre[pre_rows + k], expert[expert_rows + k]])
                     for k in range(3))  # type: ignore[return-value]

    def _value_step(self, pre_idx: torch.Tensor, expert_idx: torch.Tensor) -> float:
        """One orthogonal-gradient Adam step of ``V``; the dual's (forward) loss.

        The residual ``gamma V(s', s'') - V(s, s')`` is taken forward (the target network's
        ``V(s', s'')``, the online ``V(s, s')``) and backward (the other way round). The online
        network reads the pairs ``(s, s')`` and ``(s', s'')`` in two passes, as the authors'
        code does: the forward loss and the mean utility reach ``V`` through the first only,
        the backward loss through the second only, so each of the three gradients runs back
        through half the rows a single pass over both would hold.
        """
        opts, params = self.options, list(self.value.parameters())
        s, s1, s2 = self._triples(self.pre_rows[pre_idx], self.expert_rows[expert_idx])
        n, n_pre = len(s), len(pre_idx)
        # both networks read the same two batches of pairs: built once (frames: once scaled)
        pairs = (self.value.pair_input(s, s1), self.value.pair_input(s1, s2))
        now = self.value.from_input(pairs[0])  # (n, 2): V(s, s'), twin heads; offline first
        after = self.value.from_input(pairs[1])  # V(s', s'')
        with torch.no_grad():  # the smaller target head, for both online heads (TwinQ's min)
            both = self.value.stacked_input(*pairs)
            target = self.target.from_input(both).min(1, keepdim=True).values
        forward_residual = opts.gamma * target[n:] - now
        backward_residual = opts.gamma * after - target[:n]
        forward = opts.lam * dual_loss(forward_residual[n_pre:], forward_residual[:n_pre],
                                       opts.beta)  # fmt: skip
        backward = opts.lam * opts.eta * dual_loss(backward_residual[n_pre:],
                                                   backward_residual[:n_pre], opts.beta)
        mean_value = (1 - opts.lam) * now[:n_pre].mean()  # V(s, s') on the offline data
        g_f = torch.autograd.grad(forward, params, retain_graph=True)
        g_v = torch.autograd.grad(mean_value, params)
        g_b = torch.autograd.grad(backward, params)
        self.value_opt.zero_grad(set_to_none=True)
        for p, g, v in zip(params, orthogonal_gradient(list(g_f), list(g_b)), g_v):
            p.grad = g + v
        self.value_opt.step()
        with torch.no_grad():  # the target follows V (Polyak)
            for p, t in zip(self.value.parameters(), self.target.parameters()):
                t.lerp_(p, opts.polyak)
            for b, t in zip(self.value.buffers(), self.target.buffers()):
                t.copy_(b)  # running statistics (ResNet's), as they are
        return float(forward.detach())

    def weights(self, s: torch.Tensor, s1: torch.Tensor) -> torch.Tensor:
        """``min(exp(tau V(s, s')), clip)``, ``V`` the smaller twin head, read in evaluation
        mode (no gradient, no dropout, no update of running statistics)."""
        training = self.value.training
        self.value.eval()
        with torch.no_grad():
            v = self.value(s, s1).min(1).values
        self.value.train(training)
        return torch.exp(self.options.temperature * v).clamp_max(self.options.weight_clip)

    def _policy_step(self, idx: torch.Tensor) -> None:
        """One Adam step of the weighted log-likelihood on offline transitions ``idx``."""
        s, s1 = self.data_t.pre_pairs(idx)
        w = self.weights(s, s1)
        actions = self.data_t.pre_actions[idx].to(self.device)
        loss = (w * F.cross_entropy(self.policy(s), actions, reduction="none")).mean()
        self.policy_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.policy_opt.step()

    # -- the schedule -----------------------------------------------------------------------------

    def train_iteration(self, iteration: int) -> dict[str, float]:
        """This iteration's share of ``steps`` updates of ``V`` and ``pi``, or (converged)
        both until ``V``'s held-out dual loss stops improving, then ``pi`` alone until its
        held-out weighted loss does; diagnostics."""
        batch = int(self.config.batch_size or 1)
        self.value.train()
        self.policy.train()
        losses: list[float] = []

        def draw(rows: torch.Tensor) -> torch.Tensor:
            return rows[self.rng.integers(0, len(rows), batch)]

        def joint(n: int) -> float:
            for _ in range(n):
                losses.append(self._value_step(draw(self.pre_train), draw(self.expert_train)))
                self._policy_step(draw(self.policy_train))
            return losses[-1] if losses else float("nan")

        if self.schedule is None:
            steps = iteration_steps(self.options.steps, iteration, self.num_iterations)
            joint(steps)
            counts: dict[str, float] = {"value_steps": steps}
        else:
            value = converge(joint, self._value_score, [self.value, self.target, self.policy],
                             self.schedule, LOSS_GAIN)  # fmt: skip

            def policy_only(n: int) -> float:
                for _ in range(n):
                    self._policy_step(draw(self.policy_train))
                return float("nan")

            policy = converge(policy_only, self._policy_score, [self.policy], self.schedule,
                              LOSS_GAIN)  # fmt: skip
            counts = {"value_steps": value["updates"], "value_held_out": value["best"],
                      "policy_steps": policy["updates"], "policy_held_out": policy["best"]}
        return {"dual_loss": float(np.mean(losses[-100:])) if losses else float("nan"),
                **counts, **self.diagnostics()}  # fmt: skip

    @torch.no_grad()
    def _value_score(self) -> float:
        """Minus the dual ``L(V)`` on the held-out triples (forward residuals, the smaller
        target head), ``V`` read in evaluation mode."""
        self.value.eval()
        pre, expert = self.pre_rows[self.pre_held], self.expert_rows[self.expert_held]
        residuals, values = [], []
        for which, (rows, obs) in enumerate(((pre, self.data_t.pre_obs),
                                             (expert, self.data_t.expert_obs))):
            parts = []
            for i in range(0, len(rows), CHUNK):
                r = rows[i : i + CHUNK]
                online = self.value(obs[r], obs[r + 1])
                target = self.target(obs[r + 1], obs[r + 2]).min(1, keepdim=True).values
                parts.append(self.options.gamma * target - online)
                if which == 0:  # the mean utility is taken on the offline data
                    values.append(online)
            residuals.append(torch.cat(parts) if parts else torch.zeros(0, 2))
        self.value.train()
        if not len(pre) or not len(expert):
            return float("nan")
        opts = self.options
        loss = (opts.lam * dual_loss(residuals[1], residuals[0], opts.beta)
                + (1 - opts.lam) * torch.cat(values).mean())  # fmt: skip
        return -float(loss)

    @torch.no_grad()
    def _policy_score(self) -> float:
        """Minus the weighted log-likelihood loss on the held-out offline transitions."""
        self.policy.eval()
        held, total = self.policy_held, 0.0
        for i in range(0, len(held), CHUNK):
            idx = held[i : i + CHUNK]
            s, s1 = self.data_t.pre_pairs(idx)
            actions = self.data_t.pre_actions[idx].to(self.device)
            nll = F.cross_entropy(self.policy(s), actions, reduction="none")
            total += float((self.weights(s, s1) * nll).sum())
        self.policy.train()
        return -total / len(held) if len(held) else float("nan")

    @torch.no_grad()
    def diagnostics(self, most: int = 4096) -> dict[str, float]:
        """Mean weight of expert and offline transitions (up to ``most`` of each, evenly
        spaced), their ratio, and the share of the offline weight on transitions whose action
        is the policy's."""
        self.value.eval()
        self.policy.eval()

        def spaced(n: int) -> torch.Tensor:
            return torch.linspace(0, n - 1, min(n, most)).long()

        def chunked(pairs: Any, rows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            """Weights and the policy's actions of transitions ``rows``, CHUNK at a time."""
            out = [(self.weights(s, s1).cpu(), self.policy(s).argmax(1).cpu())
                   for s, s1 in (pairs(rows[i : i + CHUNK]) for i in range(0, len(rows), CHUNK))]
            return torch.cat([w for w, _ in out]), torch.cat([a for _, a in out])

        pre = spaced(len(self.data_t.pre_t))
        w_pre_cpu, acted = chunked(self.data_t.pre_pairs, pre)
        w_exp, _ = chunked(self.data_t.expert_pairs, spaced(len(self.data_t.expert_t)))
        w_pre = w_pre_cpu
        agree = acted == self.data_t.pre_actions[pre]
        return {"weight_expert_mean": float(w_exp.mean()),
                "weight_offline_mean": float(w_pre.mean()),
                "weight_ratio": float(w_exp.mean() / w_pre.mean().clamp_min(1e-12)),
                "offline_weight_on_policy_actions":
                    float(w_pre_cpu[agree].sum() / w_pre_cpu.sum().clamp_min(1e-12))}  # fmt: skip

    @torch.no_grad()
    def act(self, obs: np.ndarray) -> np.ndarray:
        """``argmax_a pi(a | s)`` for a batch."""
        self.policy.eval()
        return self.policy(torch.as_tensor(obs, device=self.device)).argmax(1).cpu().numpy()

    # -- state ------------------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Networks, target, optimisers and the generator's state (data only)."""
        return {"value": self.value.state_dict(), "target": self.target.state_dict(),
                "policy": self.policy.state_dict(), "value_opt": self.value_opt.state_dict(),
                "policy_opt": self.policy_opt.state_dict(),
                "rng": self.rng.bit_generator.state}  # fmt: skip

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict`."""
        self.value.load_state_dict(state["value"])
        self.target.load_state_dict(state["target"])
        self.policy.load_state_dict(state["policy"])
        self.value_opt.load_state_dict(state["value_opt"])
        self.policy_opt.load_state_dict(state["policy_opt"])
        self.rng.bit_generator.state = state["rng"]
