"""ABCO(alpha) and its baselines in one file (Monteiro, Gavenski et al., IJCNN 2020).

Algorithm 1 of the paper, top to bottom (:meth:`BCOFamily.train_iteration` then
:meth:`BCOFamily.observe`, called by the harness in :mod:`abco_train.harness.loop` for ``i =
0..alpha``; the harness also owns seeding, the datasets and the run folder):

1. ``I_s = I_pre`` (random-policy transitions with true actions).
2. Train the IDM on ``I_s`` (cross-entropy, Adam); label every expert pair ``(s_t, s_t+1)``
   with the IDM's argmax; train the policy on those labels (behavioural cloning).
3. The harness runs the greedy policy on the evaluation episodes (mazes: every layout of the
   train split); each run's ``(s_t, a_t, s_t+1)`` is a post-demonstration, ``v_e = 1`` if it
   reached the goal.
4. Re-sample ``I_s`` from ``I_pre`` and ``I_pos`` (:mod:`abco_train.methods.bco.sampling`).

Choices where the paper is loose:

* Sizes are **per class**: ``|I_s| = N`` (default ``|I_pre|``, capped by ``idm_samples``);
  ``n_pos_c = round(N * w * q_c)`` with ``w = P(g|E)`` the latest win rate and ``q_c`` the
  per-run average action distribution of the winning runs (Eq. 4 normalised);
  ``n_pre_c = round(N * (1 - w) * p_c)`` with ``p_c`` the class shares of ``I_pre`` (Eq. 6);
  largest-remainder rounding; uniform draws within a class, seeded.
* ``I_pos`` **accumulates**: Algorithm 1 appends to it and never clears it, so the winning
  runs of every iteration so far form the pool (their actions are the policy's own, hence
  true labels of those transitions). The win rate ``w`` is that of the latest iteration only:
  it measures the current policy.
* Both networks are improved, not re-initialised, across iterations ("Improve M_theta").

The IDM's health is measured, not assumed: a fixed held-out part of ``I_pre`` (true actions,
:func:`validation_split`) gives its accuracy, overall and per class, after every epoch. Each
time it trains it runs at most ``idm_epochs`` epochs, stops after ``idm_patience`` epochs
without a better validation accuracy, and keeps its best weights. Its health checks
(:mod:`abco_train.methods.bco.health`) are logged every iteration and never stop the run;
with ``idm_reinit`` an IDM at chance is re-initialised and trained once more.

With a ``--budget`` (environment interactions), ``I_pre`` is the first ``budget`` transitions
at most, and the harness cuts the runs learned from at the budget left. Budgets are equal
across variants: a variant that runs one iteration (``bc``, ``bco``) trains its policy for as
many epochs as the iterative ones do over all their iterations, ``policy_epochs *
(first_epochs_factor + iterations)``, so no baseline is behind on epochs. With
``min_updates`` (the ``general`` preset's), ``policy_epochs`` and ``idm_epochs`` are first
raised on small data until one such unit makes at least that many minibatch updates (the
first K layouts of the procedural datasets range from 850 to 84,000 expert transitions);
with ``max_updates`` (the ``general`` preset's too) a policy unit makes at most that many, so
every K trains its policy for the same number of updates (the IDM's set is ``idm_samples``
for every K already).

Variants (switches of one implementation, see :data:`VARIANTS`): ``bc`` (policy on the true
expert actions), ``bco`` (BCO(0): IDM on ``I_pre`` once), ``bco-alpha`` (IDM re-trained on all
post-demonstrations, the ABCO paper's reading of BCO(alpha)), ``bco-alpha-torabi`` (Torabi et
al.'s BCO(alpha): ``I_pre`` plus every post-demonstration so far), ``abco`` (attention +
partial sampling), and Table 2's ablations: ``attention`` (attention, BCO(alpha) data),
``sampling-partial``, ``sampling-whole`` (no attention), ``abco-whole`` (attention + whole).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from abco_data.torch_view import frames_tensor
from abco_train.config.run import RunConfig
from abco_train.harness.rollouts import Rollouts
from abco_train.harness.training_data import TrainingData
from abco_train.methods.base import Method
from abco_train.methods.bco.converged import expert_split, fit_converged
from abco_train.methods.bco.fitting import fit, predict, validation_split
from abco_train.methods.bco.health import DEAD_MARGIN, MIN_JUDGED, label_health
from abco_train.methods.bco.idm import IDMTraining
from abco_train.methods.bco.options import VARIANTS, BCOOptions, resolved
from abco_train.methods.bco.sampling import sample_training_set
from abco_train.methods.converged import schedule_of
from abco_train.methods.registry import register
from abco_train.networks.builders import build_networks, data_statistics

__all__ = ["VARIANTS", "BCOFamily", "DEAD_MARGIN", "MIN_JUDGED"]



@register(*VARIANTS)
class BCOFamily(IDMTraining, Method):
    """BC, BCO, BCO(alpha) and ABCO(alpha): one implementation with the switches of
    :data:`VARIANTS` (see the module docstring)."""

    @classmethod
    def variant(cls, name: str) -> dict[str, Any]:
        """The switches of the method registered as ``name`` (a subclass may add its own)."""
        return VARIANTS[name]

    @classmethod
    def defaults(cls, name: str) -> Mapping[str, Any]:
        """The variant's attention switch (``--attention`` overrides it)."""
        return {"attention": cls.variant(name)["attention"]}

    Options = BCOOptions
    options: BCOOptions

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        super().__init__(config, data, rng)
        variant = self.variant(config.method)
        self.idm_data, self.iterative = variant["idm_data"], variant["iterative"]
        # I_pre: with a --budget, the first transitions it pays for (every one is counted).
        paid = self.budget_left if self.idm_data is not None else None  # None: all of them
        pre_t, pre_actions = data.pre_t[:paid], data.pre_actions[:paid]
        # -- networks (mean/std of the states standardise vector inputs) ----------------------
        stats = data_statistics(config.env, data.pre_obs, pre_t, len(pre_t) < len(data.pre_t))
        self.net_stats = stats
        self.augment = self.options.augment == "transpose"
        self.policy, self.idm = build_networks(
            data.observation_space, data.n_actions, config.arch, bool(config.attention),
            resolved(self.options.idm_input), **stats,
        )
        # Networks and observations live on the run's device: on a GPU the frames (a maze's
        # as what draws them, a few bytes a row) move there once and minibatches are gathered
        # there. Indices and labels stay in CPU memory, where the sampling draws them.
        self.device = torch.device(config.device)
        self.policy, self.idm = self.policy.to(self.device), self.idm.to(self.device)
        self.policy_opt = torch.optim.Adam(self.policy.parameters(), lr=resolved(config.lr))
        self.idm_opt = torch.optim.Adam(self.idm.parameters(), lr=resolved(config.lr))
        # -- data as torch tensors (no copies) ------------------------------------------------
        self.pre_obs = frames_tensor(data.pre_obs, self.device)
        if self.idm_data is None:  # BC has no IDM to measure
            keep, held = np.arange(len(pre_t)), np.zeros(0, dtype=np.int64)
        else:
            keep, held = validation_split(len(pre_t), self.options.idm_validation, config.seed)
        self.pre_t = torch.from_numpy(pre_t[keep])
        self.pre_actions = torch.from_numpy(pre_actions[keep])
        if self.idm_data is not None:  # its IDM learns from (and is measured on) all of I_pre
            self.count("pre_demonstration", len(pre_t))
        self.val_t = torch.from_numpy(pre_t[held])
        self.val_actions = torch.from_numpy(pre_actions[held])
        shares = np.bincount(pre_actions[held], minlength=data.n_actions) / max(len(held), 1)
        self.chance = float(shares.max())
        self.expert_obs = frames_tensor(data.expert_obs, self.device)
        self.expert_t = torch.from_numpy(data.expert_t)
        # -- the schedule: epochs, or each fit until its held-out score stops improving ------
        self.schedule = schedule_of(self.options)
        rows, held = np.arange(len(data.expert_t)), np.zeros(0, dtype=np.int64)
        if self.schedule is not None:
            rows, held = expert_split(len(data.expert_t), config.seed)  # the policy's check
        self.policy_rows, self.policy_held = torch.from_numpy(rows), torch.from_numpy(held)
        # -- I_pos (accumulated post-demonstrations) and the current I_s ----------------------
        self.pos_obs = torch.zeros((0, *data.pre_obs.shape[1:]), dtype=self.pre_obs.dtype,
                                   device=self.device)
        self.pos_t = torch.zeros(0, dtype=torch.long)
        self.pos_actions = torch.zeros(0, dtype=torch.long)
        self.pos_runs = np.zeros(0, dtype=np.int64)
        self.pos_wins = np.zeros(0, dtype=bool)
        size = min(len(self.pre_t), self.options.idm_samples or len(self.pre_t))
        self.s_pre = torch.from_numpy(rng.choice(len(self.pre_t), size, replace=False))
        self.s_pos = torch.zeros(0, dtype=torch.long)
        self.labels: np.ndarray | None = None

    @property
    def num_iterations(self) -> int:
        """``alpha + 1`` for iterative variants, else 1."""
        return int(resolved(self.config.iterations)) + 1 if self.iterative else 1

    # -- Algorithm 1, one iteration ---------------------------------------------------------

    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Improve the IDM on ``I_s``, label the expert pairs, clone them into the policy."""
        cfg, stats = self.config, {}
        factor = resolved(self.options.first_epochs_factor)
        boost = factor if iteration == 0 else 1
        # One-iteration variants get the iterative ones' whole policy budget (equal epochs).
        units = boost if self.iterative else factor + resolved(cfg.iterations)
        policy_epochs, policy_updates = self._policy_budget(units)
        expert_n = len(self.expert_t)
        true = torch.from_numpy(self.data.expert_eval_actions)
        if self.idm_data is None:  # BC: the supervised reference, true expert actions
            labels = true
        else:
            if iteration == 0 or self.idm_data != "pre":
                idm_set = len(self.s_pre) + len(self.s_pos)
                idm_epochs = self._floored(resolved(self.options.idm_epochs), idm_set)
                stats.update(self._train_idm_checked(idm_epochs * boost))
                stats["idm_samples"] = int(len(self.s_pre) + len(self.s_pos))
            labels = predict(self.idm, self._expert_pairs, expert_n, device=self.device)
            stats["idm_expert_accuracy"] = float((labels == true).float().mean())
            stats.update(label_health(labels.numpy(), self.data.n_actions))
        self.labels = labels.numpy()
        stats.update(self._fit_policy(labels, policy_epochs, policy_updates))
        predicted = predict(self.policy, lambda idx: (self.expert_obs[self.expert_t[idx]],),
                             expert_n, device=self.device)  # fmt: skip
        stats["policy_label_accuracy"] = float((predicted == labels).float().mean())
        return stats

    def _fit_policy(self, labels: torch.Tensor, epochs: int, updates: int) -> dict[str, Any]:
        """Clone ``labels`` into the policy: ``epochs`` (at most ``updates`` minibatches), or
        with the converged schedule until its agreement with the labels of the held-out
        expert transitions stops improving."""
        rows, held, batch = self.policy_rows, self.policy_held, resolved(self.config.batch_size)
        common = {"desc": "policy", "quiet": self.config.quiet, "device": self.device,
                  "augment": self.augment}  # fmt: skip

        def states(subset: torch.Tensor) -> Any:
            return lambda idx: (self.expert_obs[self.expert_t[subset[idx]]],)

        if self.schedule is None:
            loss = fit(self.policy, self.policy_opt, states(rows), labels[rows], epochs, batch,
                       self.rng, max_batches=updates, **common)  # fmt: skip
            return {"policy_loss": loss, "policy_epochs": epochs, "policy_updates": updates}

        def agreement() -> float:
            if len(held) == 0:
                return float("nan")
            pred = predict(self.policy, states(held), len(held), device=self.device)
            return float((pred == labels[held]).float().mean())

        out = fit_converged(self.policy, self.policy_opt, states(rows), labels[rows], agreement,
                            self.schedule, batch, self.rng, **common)  # fmt: skip
        return {"policy_loss": out["loss"], "policy_updates": int(out["updates"]),
                "policy_held_out_agreement": out["best"]}

    def _policy_budget(self, units: int) -> tuple[int, int]:
        """Epochs and minibatch updates of ``units`` policy units: ``policy_epochs`` each
        (floored with ``min_updates``), a unit cut to ``max_updates`` updates where one makes
        more (the last epoch then stops part-way)."""
        per_epoch = -(-len(self.expert_t) // resolved(self.config.batch_size))
        epochs = self._floored(resolved(self.options.policy_epochs), len(self.expert_t))
        per_unit = epochs * per_epoch
        if self.options.max_updates:
            per_unit = min(per_unit, self.options.max_updates)
        updates = units * per_unit
        return -(-updates // max(per_epoch, 1)), updates

    def _floored(self, epochs: int, examples: int) -> int:
        """``epochs`` raised, with ``min_updates``, until they make that many minibatches."""
        least = self.options.min_updates
        if not least or not examples:
            return epochs
        per_epoch = -(-examples // resolved(self.config.batch_size))
        return max(epochs, -(-least // per_epoch))

    def _expert_pairs(self, idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        rows = self.expert_t[idx]
        return self.expert_obs[rows], self.expert_obs[rows + 1]

    # -- post-demonstrations and the next I_s --------------------------------------------------

    def learns_from_rollouts(self, iteration: int) -> bool:
        """Iterative variants with an IDM learn from every iteration's runs but the last's."""
        return self.iterative and self.idm_data is not None and iteration + 1 < self.num_iterations

    def observe(self, iteration: int, rollouts: Rollouts) -> dict[str, float]:
        """Append the runs to ``I_pos`` and re-sample ``I_s`` for the next iteration."""
        if not self.iterative or self.idm_data is None or rollouts.observations is None:
            return {}
        # recorded runs: their actions, obs_t and run_ids come with the observations
        assert (rollouts.actions is not None and rollouts.obs_t is not None
                and rollouts.run_ids is not None)  # fmt: skip
        if self.learns_from_rollouts(iteration):  # the last iteration's runs train nothing
            self.count("post_demonstration", int(rollouts.lengths.sum()))
        keep_all = self.idm_data in ("pos", "pre+pos", "whole")
        runs = np.arange(len(rollouts.successes))
        keep = runs if keep_all else runs[rollouts.successes]
        offset = int(self.pos_wins.shape[0])
        if len(keep):
            sel = np.isin(rollouts.run_ids, keep)
            obs_rows = np.unique(np.concatenate([rollouts.obs_t[sel], rollouts.obs_t[sel] + 1]))
            remap = np.full(len(rollouts.observations), -1, dtype=np.int64)
            remap[obs_rows] = np.arange(len(obs_rows)) + len(self.pos_obs)
            new_obs = torch.from_numpy(rollouts.observations[obs_rows]).to(self.device)
            self.pos_obs = torch.cat([self.pos_obs, new_obs])
            self.pos_t = torch.cat([self.pos_t, torch.from_numpy(remap[rollouts.obs_t[sel]])])
            new_actions = torch.from_numpy(rollouts.actions[sel])
            self.pos_actions = torch.cat([self.pos_actions, new_actions])
            self.pos_runs = np.concatenate([self.pos_runs, offset + rollouts.run_ids[sel]])
        self.pos_wins = np.concatenate([self.pos_wins, rollouts.successes])
        if self.idm_data == "pre+pos":  # Torabi et al.: I_pre and every post-demonstration
            self.s_pos = torch.arange(len(self.pos_t))
            return {"pos_transitions": len(self.pos_t), "is_from_pos": len(self.s_pos),
                    "is_from_pre": len(self.s_pre)}  # fmt: skip
        if self.idm_data == "pos":  # BCO(alpha): every post-demonstration so far
            self.s_pre = torch.zeros(0, dtype=torch.long)
            self.s_pos = torch.arange(len(self.pos_t))
            if len(self.s_pos) == 0:  # nothing recorded yet: keep I_pre
                self.s_pre = torch.arange(len(self.pre_t))
            return {"pos_transitions": len(self.pos_t)}
        size = min(len(self.pre_t), self.options.idm_samples or len(self.pre_t))
        sample = sample_training_set(
            self.pre_actions.numpy(), self.pos_actions.numpy(), self.pos_runs, self.pos_wins,
            size, self.rng, mode=self.idm_data, win_rate=rollouts.win_rate,
            n_actions=self.data.n_actions,
        )  # fmt: skip
        self.s_pre = torch.from_numpy(sample.pre_indices)
        self.s_pos = torch.from_numpy(sample.pos_indices)
        return {"pos_transitions": len(self.pos_t), "is_from_pos": len(self.s_pos),
                "is_from_pre": len(self.s_pre)}  # fmt: skip

    # -- acting, labels and state ---------------------------------------------------------------

    @torch.no_grad()
    def act(self, obs: np.ndarray) -> np.ndarray:
        """Greedy actions of the policy for a batch of observations."""
        self.policy.eval()
        return self.policy(torch.as_tensor(obs, device=self.device)).argmax(1).cpu().numpy()

    def expert_labels(self) -> np.ndarray | None:
        """The labels the policy was last trained on (IDM predictions of the expert pairs)."""
        return self.labels

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume: nets, optimisers, I_pos, I_s, labels, rng (data:
        tensors, numpy arrays, the generator's state of ints)."""
        return {
            "policy": self.policy.state_dict(), "idm": self.idm.state_dict(),
            "policy_opt": self.policy_opt.state_dict(), "idm_opt": self.idm_opt.state_dict(),
            "pos_obs": self.pos_obs, "pos_t": self.pos_t, "pos_actions": self.pos_actions,
            "pos_runs": self.pos_runs, "pos_wins": self.pos_wins,
            "s_pre": self.s_pre, "s_pos": self.s_pos, "labels": self.labels,
            "rng": self.rng.bit_generator.state,
        }  # fmt: skip

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`.

        Raises:
            TypeError: A kept set that is not the array :meth:`state_dict` stores there.
        """
        kinds = {"pos_obs": torch.Tensor, "pos_t": torch.Tensor, "pos_actions": torch.Tensor,
                 "pos_runs": np.ndarray, "pos_wins": np.ndarray, "s_pre": torch.Tensor,
                 "s_pos": torch.Tensor, "labels": (np.ndarray, type(None))}  # fmt: skip
        wrong = [key for key, kind in kinds.items() if not isinstance(state[key], kind)]
        if wrong:
            raise TypeError(f"not the arrays a state of {type(self).__name__} keeps: {wrong}")
        self.policy.load_state_dict(state["policy"])
        self.idm.load_state_dict(state["idm"])
        self.policy_opt.load_state_dict(state["policy_opt"])
        self.idm_opt.load_state_dict(state["idm_opt"])
        for key in ("pos_obs", "pos_t", "pos_actions", "pos_runs", "pos_wins", "s_pre", "s_pos",
                    "labels"):  # fmt: skip
            setattr(self, key, state[key])
        self.rng.bit_generator.state = state["rng"]
