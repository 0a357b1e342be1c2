"""GAIfO: Generative Adversarial Imitation from Observation (Torabi, Warnell and Stone, 2018).

GAIfO imitates from expert *state transitions* alone: a discriminator learns to tell the
expert's transitions ``(s, s')`` from the learner's, and the learner maximises, by
reinforcement learning in the environment, a reward that is high where the discriminator
mistakes it for the expert. The paper's objective is GAIL's with the state-action occupancy
measure replaced by the state-transition one ``rho_pi(s, s')``::

    min_pi  max_{D in (0,1)^{S x S}}   E_{rho_pi}[ log D(s, s') ] + E_{rho_E}[ log(1 - D(s, s')) ]

and its Algorithm 1 alternates, from a random policy and discriminator: (a) run the policy
and store its transitions ``tau_i = {(s, s')}``; (b) update ``D`` by a gradient step of the
objective on ``tau_i`` against the demonstrations ``tau_E``; (c) update the policy (TRPO in
the paper) with the cost ``log D(s, s')``. Here is where each piece lives:

* **Discriminator** (:func:`build_discriminator`): abco's inverse-dynamics network read as a
  binary classifier, one logit ``l(s, s')`` instead of action logits: vectors, an MLP on the
  standardised ``(s, s' - s)`` (mean and std of the *expert's* pairs; GAIfO uses no
  pre-demonstrations); frames, the compact CNN on the frame and the frame difference (six
  channels). **Label convention**: abco's ``D(s, s') = sigmoid(l)`` is the probability that
  the pair is the *expert's*, expert pairs labelled **1**, the learner's **0** — the paper's
  ``D`` is ``1 - D`` here (the paper labels the learner 1). Step (b) is the binary
  cross-entropy ``-E_E[log D] - E_pi[log(1 - D)]``, the negated objective above, over
  equal-sized minibatches of expert and learner pairs (:meth:`GAIfO.update_discriminator`).
* **Reward** (:func:`reward_from_logits`), option ``reward``; which one fits depends on how
  the env's episodes end, because a reward of one sign everywhere rewards or punishes the
  episode's length itself:

  - ``logit`` (default): ``r = log D - log(1 - D) = l``. At the optimal discriminator
    ``D* = rho_E / (rho_E + rho_pi)`` it is ``log rho_E(s, s') - log rho_pi(s, s')``, whose
    expectation under the learner is ``-KL(rho_pi || rho_E)``: the return measures the
    divergence from the expert's transitions, with no sign of its own. While ``D`` wins
    (most of training) it is mostly negative, a push towards ending episodes: right where an
    episode ends *by reaching the goal* (Acrobot, MountainCar, the mazes).
  - ``gail`` (CartPole's default): ``r = -log(1 - D)``, the paper's own (GAIL's cost
    ``log D_paper`` negated), always positive: a bonus for every step survived, right where
    an episode ends *by failing* (CartPole; with ``logit`` its learner learnt to fall at
    once: AER 9 on seeds 100-102, against 500 with ``gail``), wrong where it ends at the
    goal (Acrobot seed 100: AER -211 with ``gail``, -88 with ``logit``: the learner keeps
    swinging instead of finishing).
  - ``log_d``: ``r = log D``, always negative (a cost per step); for comparison.
  - Rewards are clipped to ``[-reward_clip, reward_clip]``.

* **RL learner** (:mod:`abco_train.methods.gaifo.sb3`): stable-baselines3's PPO (step (c)
  with PPO instead of TRPO; SB3 is imported once a run starts, the optional extra
  ``abco[rl]``) in a vector env of the run's environment whose reward is replaced by a
  VecEnv wrapper (:class:`~abco_train.methods.gaifo.sb3.DiscriminatorReward`): for every step of
  all ``n_envs`` envs at once it computes ``r = f(l(s, s'))`` with ``s'`` the env's terminal
  observation where an episode ended (SB3 returns the next episode's first observation
  there), and it stores the pairs for step (b). The env's own reward never reaches PPO (the
  Monitor keeps the true return for the log only). Termination and truncation pass through
  unchanged: SB3 bootstraps the value of truncated episodes (``TimeLimit.truncated``) and
  not of terminated ones. Mazes train on the train split with the env's own resets: each
  episode a layout drawn from the split, start ``(0, 0)``, as in evaluation. Where the
  settings say ``normalize`` (the Zoo's), SB3's ``VecNormalize`` sits between that wrapper
  and PPO: ``D`` sees raw observations, PPO standardised ones (vectors) and scaled rewards,
  and :meth:`act` standardises by the same statistics (checkpointed).
* **Adversarial loop** (:meth:`GAIfO.train_iteration`): one *round* is one PPO rollout of
  ``n_steps * n_envs`` env steps with the current ``D``'s rewards followed by PPO's update
  (``n_epochs`` epochs of minibatches ``batch_size``), then ``d_epochs`` passes of ``D``
  over that rollout's pairs, each learner minibatch of ``d_batch_size`` against as many
  expert pairs drawn uniformly (steps (a), (c), (b)). The run's PPO steps, ``rl_steps``
  capped by the run's ``--budget``, rounded *down* to whole rounds (SB3's ``learn()`` runs
  whole rollouts: rounding down keeps it within the budget), are spread evenly over the
  harness's iterations (the last takes what is left), each of which is then evaluated by the
  harness (greedy: PPO's deterministic actions, :meth:`act`). A budget below one round ends
  the run with status ``budget_too_small``. PPO's linear schedules (``*_schedule``) run over
  these planned steps, not over one ``learn()`` call (:class:`~.sb3.RunSchedule`).

Every PPO env step is counted as ``rl`` (SB3's ``num_timesteps``, which every iteration
restarts), never past the budget; the method uses no pre-demonstrations and learns nothing
from the harness's evaluation runs, so both other counts stay 0. Expert actions are never
read.

Seeding: ``D`` is initialised from torch's generator (seeded by the harness); PPO gets
``seed=`` derived from the run's seed (SB3 then re-seeds python, numpy's and torch's global
generators with it); its env resets and numpy's global generator (PPO's minibatch order)
are re-seeded from ``(seed, iteration)`` at the start of every iteration, whose first PPO
rollout restarts the env's episodes (``learn(reset_num_timesteps=True)``), so that a run
resumed from a checkpoint continues exactly as an
uninterrupted one (torch's generator, PPO's action draws, is checkpointed by the harness).
Same seed, same run on CPU.

Settings are :class:`~abco_train.methods.gaifo.options.GAIfOOptions` (``--gaifo-*`` flags or
``config.method_options``) over the RL Baselines3 Zoo's published PPO hyperparameters per
environment family (:data:`~abco_train.methods.gaifo.options.ZOO_PPO`, sources there) and
GAIfO's own :data:`~abco_train.methods.gaifo.options.GAIFO_DEFAULTS`; the RunConfig fields of
ABCO's networks (``lr``, ``batch_size``, epochs) are not used, ``arch`` and ``attention``
choose the image discriminator's network.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
import torch.nn.functional as F

import abco_envs
from abco_data.torch_view import frames_tensor
from abco_train.config.run import ConfigError, RunConfig, env_kind
from abco_train.harness.runtime import derived_seed
from abco_train.harness.training_data import TrainingData
from abco_train.methods.base import Method, TrainingFailed
from abco_train.methods.gaifo.options import GAIFO_DEFAULTS, REWARDS, GAIfOOptions
from abco_train.methods.registry import register
from abco_train.networks.builders import build_networks
from abco_train.networks.heads import IDMNet

if TYPE_CHECKING:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from abco_train.methods.gaifo.sb3 import DiscriminatorReward

__all__ = ["GAIfO", "GAIfOOptions", "GAIFO_DEFAULTS", "REWARDS", "build_discriminator",
           "reward_from_logits", "EXPERT_LABEL", "LEARNER_LABEL", "SB3_INSTALL"]  # fmt: skip

#: The discriminator's label of expert pairs; the learner's pairs get :data:`LEARNER_LABEL`.
EXPERT_LABEL = 1.0
LEARNER_LABEL = 0.0

SB3_INSTALL = 'pip install "abco[rl]"  (or: pip install "stable-baselines3>=2.3")'

#: Tags of the seeds derived from the run's seed (one stream each).
_SB3_SEED, _ITERATION_SEED = 0x6A1F0, 0x6A1F1


def _require_sb3() -> None:
    """Raise :class:`ConfigError` with the install command when stable-baselines3 is missing."""
    try:
        import stable_baselines3  # noqa: F401
    except ImportError as exc:
        raise ConfigError(f"method gaifo needs stable-baselines3 (its PPO learner): "
                          f"{SB3_INSTALL}") from exc  # fmt: skip


# -- the discriminator -------------------------------------------------------------------------


def build_discriminator(data: TrainingData, arch: str | None, attention: bool = False,
                        hidden: int = 64, env_id: str | None = None) -> IDMNet:  # fmt: skip
    """``D``'s network: one logit for a batch of pairs ``(s, s')`` (``net(s, s1) -> (B, 1)``).

    abco's IDM in its ``difference`` form with one output: vectors standardised by the mean
    and std of the expert's ``s`` and ``s' - s``; frames (uint8) through ``arch`` on the
    frame and the frame difference (``arch`` ``None``: ``mlp`` or ``cnn`` from the space); a
    maze's (``env_id``) cell networks (``cellnet``, ``cellplan``) also get its grid size.
    """
    stats: dict[str, Any] = {}
    if len(data.observation_space.shape) == 1:
        s = data.expert_obs[data.expert_t].astype(np.float64)
        d = data.expert_obs[data.expert_t + 1].astype(np.float64) - s
        stats = {"obs_mean": s.mean(0), "obs_std": s.std(0), "delta_mean": d.mean(0),
                 "delta_std": d.std(0)}  # fmt: skip
    elif env_id is not None and abco_envs.is_maze(abco_envs.env_name(env_id)):  # cell nets read it
        stats = {"grid": abco_envs.maze_size(env_id)}
    _, net = build_networks(data.observation_space, 1, arch, attention, "difference",
                            hidden=hidden, **stats)  # fmt: skip
    return net


def reward_from_logits(logits: torch.Tensor, form: str = "logit",
                       clip: float | None = None) -> torch.Tensor:  # fmt: skip
    """The learner's reward from ``D``'s logits ``l`` (``D = sigmoid(l)``, expert = 1).

    ``logit``: ``log D - log(1 - D) = l``; ``gail``: ``-log(1 - D) = softplus(l)`` (the
    paper's); ``log_d``: ``log D = -softplus(-l)``. All increase with ``D``.

    Example:
        >>> l = torch.tensor([-2.0, 0.0, 2.0])
        >>> reward_from_logits(l).tolist(), reward_from_logits(l, "gail")[1].item() > 0
        ([-2.0, 0.0, 2.0], True)
    """
    if form == "logit":
        reward = logits
    elif form == "gail":
        reward = F.softplus(logits)
    elif form == "log_d":
        reward = -F.softplus(-logits)
    else:
        raise ValueError(f"unknown reward {form!r}; expected one of {REWARDS}")
    return reward if clip is None else reward.clamp(-clip, clip)


# -- the method -------------------------------------------------------------------------------


@register("gaifo")
class GAIfO(Method):
    """GAIfO with a PPO learner (see the module docstring)."""

    @classmethod
    def defaults(cls, name: str) -> Mapping[str, Any]:
        """No attention in the discriminator by default; needs stable-baselines3.

        Raises:
            ConfigError: stable-baselines3 is not installed (the message has the pip command).
        """
        _require_sb3()
        return {"attention": False}

    Options = GAIfOOptions
    options: GAIfOOptions

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        super().__init__(config, data, rng)
        _require_sb3()
        from abco_train.methods.gaifo import sb3  # stable-baselines3: only once a run starts

        opt = self.options
        self.device = torch.device(config.device)
        # -- the discriminator, from torch's generator (seeded by the harness) ---------------
        self.discriminator = build_discriminator(
            data, config.arch, bool(config.attention), opt.d_hidden, config.env).to(self.device)
        self.d_opt = torch.optim.Adam(self.discriminator.parameters(), lr=opt.d_lr)
        self.expert_obs = frames_tensor(data.expert_obs)
        self.expert_t = torch.from_numpy(data.expert_t)
        # -- the learner's env (the run's env, its reward replaced by D's) and its PPO --------
        maze = env_kind(config.env) == "maze"
        kwargs = {**data.env_kwargs, "split": "train"} if maze else dict(data.env_kwargs)
        self.env: DiscriminatorReward = sb3.learner_env(config.env, kwargs, opt.n_envs,
                                                        self.reward)  # fmt: skip
        self.normalizer: VecNormalize | None = sb3.normalizer(self.env, opt, frames=maze)
        self.progress = sb3.RunProgress()  # the linear schedules' clock (train_iteration)
        self.model: PPO = sb3.make_ppo(
            self.normalizer or self.env, opt, frames=maze, progress=self.progress,
            seed=derived_seed(config.seed, _SB3_SEED), device=self.device)  # fmt: skip
        # -- the plan: the run's PPO steps in whole rollouts, within its budget -------------
        self.round_steps = opt.rollout_steps
        # GAIfO spends nothing but RL steps, so the budget left now is what learning may use;
        # rounding down keeps PPO (whose learn() runs whole rollouts) within it.
        left = self.budget_left
        steps = opt.rl_steps if left is None else min(opt.rl_steps, left)
        self.rounds_total = steps // self.round_steps

    # -- the reward and the discriminator's updates ------------------------------------------

    @torch.no_grad()
    def logits(self, s: np.ndarray | torch.Tensor, s1: np.ndarray | torch.Tensor) -> torch.Tensor:
        """``D``'s logits ``l(s, s')`` of a batch of pairs (on CPU); ``D = sigmoid(l)``."""
        self.discriminator.eval()
        out = self.discriminator(torch.as_tensor(s, device=self.device),
                                 torch.as_tensor(s1, device=self.device))  # fmt: skip
        return out.squeeze(1).float().cpu()

    def reward(self, s: np.ndarray, s1: np.ndarray) -> np.ndarray:
        """The learner's reward of a batch of its transitions (``reward`` option)."""
        form, clip = self.options.reward, self.options.reward_clip
        return reward_from_logits(self.logits(s, s1), form, clip).numpy()

    def update_discriminator(self, learner_s: np.ndarray, learner_s1: np.ndarray
                             ) -> dict[str, float]:  # fmt: skip
        """``d_epochs`` passes over the learner's pairs: binary cross-entropy with each learner
        minibatch labelled :data:`LEARNER_LABEL` and as many uniformly drawn expert pairs
        labelled :data:`EXPERT_LABEL`. Returns the last pass's mean loss and accuracies."""
        opt, net = self.options, self.discriminator
        n, batch = len(learner_s), opt.d_batch_size
        pairs_s, pairs_s1 = torch.from_numpy(learner_s), torch.from_numpy(learner_s1)
        net.train()
        loss_sum = hits_e = hits_l = seen = 0.0
        for _ in range(opt.d_epochs):
            loss_sum = hits_e = hits_l = seen = 0.0
            order = torch.from_numpy(self.rng.permutation(n))
            for start in range(0, n, batch):
                idx = order[start : start + batch]
                rows = self.expert_t[torch.from_numpy(self.rng.integers(0, len(self.expert_t),
                                                                        len(idx)))]
                s = torch.cat([self.expert_obs[rows], pairs_s[idx]]).to(self.device)
                s1 = torch.cat([self.expert_obs[rows + 1], pairs_s1[idx]]).to(self.device)
                labels = torch.cat([torch.full((len(idx),), EXPERT_LABEL),
                                    torch.full((len(idx),), LEARNER_LABEL)]).to(self.device)
                logits = net(s, s1).squeeze(1)
                loss = F.binary_cross_entropy_with_logits(logits, labels)
                self.d_opt.zero_grad(set_to_none=True)
                loss.backward()
                self.d_opt.step()
                with torch.no_grad():
                    said_expert = (logits > 0).float()
                    hits_e += float(said_expert[: len(idx)].sum())
                    hits_l += float((1 - said_expert[len(idx) :]).sum())
                loss_sum += loss.item() * len(idx)
                seen += len(idx)
        if not np.isfinite(loss_sum):
            raise TrainingFailed("discriminator_diverged",
                                 "the discriminator's loss is not finite", {"d_loss": loss_sum})
        return {"d_loss": loss_sum / max(seen, 1), "d_expert_accuracy": hits_e / max(seen, 1),
                "d_learner_accuracy": hits_l / max(seen, 1)}  # fmt: skip

    # -- the adversarial loop ------------------------------------------------------------------

    def rounds_by(self, iteration: int) -> int:
        """Rounds planned for iterations ``0..iteration`` together: the run's rounds spread
        evenly over its iterations (earlier ones get the remainder)."""
        per, extra = divmod(self.rounds_total, self.num_iterations)
        return per * (iteration + 1) + min(iteration + 1, extra)

    def rounds_of(self, iteration: int) -> int:
        """Rounds iteration ``iteration`` runs: the plan's up to it less the rounds already run
        (the last iteration takes what is left), never more than the budget left pays for.

        Raises:
            TrainingFailed: ``budget_too_small``: the run's budget cannot pay for one PPO
                rollout.
        """
        if self.rounds_total == 0:  # options.check keeps rl_steps >= one rollout: the budget
            rollout, opt = self.round_steps, self.options
            raise TrainingFailed(
                "budget_too_small",
                f"the run's --budget of {self.config.budget:,} interactions cannot pay for one "
                f"PPO rollout of {rollout:,} env steps (--gaifo-n-steps {opt.n_steps} x "
                f"--gaifo-n-envs {opt.n_envs}); give a budget of at least {rollout:,} or "
                "smaller rollouts",
                {"budget": self.config.budget, "rollout_steps": rollout})  # fmt: skip
        done = self.interactions["rl"] // self.round_steps
        rounds = max(0, self.rounds_by(iteration) - done)
        left = self.budget_left
        return rounds if left is None else min(rounds, left // self.round_steps)

    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Rounds of PPO on D's rewards, each followed by D's update on its pairs."""
        model, env = self.model, self.env
        seed = derived_seed(self.config.seed, _ITERATION_SEED, iteration)
        np.random.seed(seed)  # noqa: NPY002 -- PPO draws its minibatch order from it
        env.seed(seed)  # the next reset seeds the episodes (exact resuming)
        rounds = self.rounds_of(iteration)
        done = self.interactions["rl"] // self.round_steps
        t_rl = t_d = 0.0
        stats: dict[str, Any] = {}
        rewards: list[float] = []
        for k in range(rounds):
            before, t0 = (0 if k == 0 else model.num_timesteps), time.perf_counter()
            # the run's progress after this rollout, as SB3 computes it within one learn()
            # call: the linear schedules reach 0 at the run's last update (the Zoo's lin_)
            self.progress.remaining = 1.0 - (done + k + 1) / self.rounds_total
            # The iteration's first round starts afresh (reset_num_timesteps): SB3 resets the
            # env (the seeded episodes above) and empties its episode log (this iteration's
            # episodes only); with constant schedules its step count steers nothing else.
            model.learn(self.round_steps, reset_num_timesteps=k == 0)
            self.count("rl", model.num_timesteps - before)
            t1 = time.perf_counter()
            s, s1, r = env.take_pairs()
            rewards.append(float(r.mean()))
            stats = self.update_discriminator(s, s1)
            t_rl, t_d = t_rl + t1 - t0, t_d + time.perf_counter() - t1
        episodes = list(model.ep_info_buffer or []) if rounds else []
        stats.update({
            "rounds": rounds, "rl_steps": rounds * self.round_steps,
            "reward_mean": float(np.mean(rewards)) if rewards else float("nan"),
            "reward_first_round": rewards[0] if rewards else float("nan"),
            "reward_last_round": rewards[-1] if rewards else float("nan"),
            # the env's own return and length of PPO's recent episodes: a diagnostic only
            "rl_env_return": float(np.mean([e["r"] for e in episodes])) if episodes else
            float("nan"),
            "rl_episode_length": float(np.mean([e["l"] for e in episodes])) if episodes else
            float("nan"),
            "seconds_rl": t_rl, "seconds_discriminator": t_d,
        })  # fmt: skip
        if iteration == 0:
            stats["options"] = self.options.to_dict()  # the run's effective settings
            stats["rl_steps_planned"] = self.rounds_total * self.round_steps
        return stats

    # -- acting and state -----------------------------------------------------------------------

    def act(self, obs: np.ndarray) -> np.ndarray:
        """PPO's deterministic (most probable) actions for a batch of observations."""
        seen: Any = np.asarray(obs)
        if self.normalizer is not None:  # PPO learnt on normalised observations
            seen = self.normalizer.normalize_obs(seen)
        actions, _ = self.model.predict(seen, deterministic=True)
        return np.asarray(actions, dtype=np.int64).reshape(-1)

    def state_dict(self) -> dict[str, Any]:
        """PPO's networks and optimiser, the normaliser's statistics, D and its optimiser, the
        rng: data, tensors and ints. (PPO's step count is not needed: every iteration restarts
        it, :meth:`train_iteration`; the schedules' progress follows from the ``rl`` count.)"""
        from abco_train.methods.gaifo import sb3

        norm = self.normalizer
        return {
            "policy": self.model.policy.state_dict(),
            "policy_opt": self.model.policy.optimizer.state_dict(),
            "normalizer": {} if norm is None else sb3.normalizer_state(norm),
            "discriminator": self.discriminator.state_dict(), "d_opt": self.d_opt.state_dict(),
            "rng": self.rng.bit_generator.state,
        }  # fmt: skip

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (an older checkpoint's ``num_timesteps`` is not read)."""
        from abco_train.methods.gaifo import sb3

        self.model.policy.load_state_dict(state["policy"])
        self.model.policy.optimizer.load_state_dict(state["policy_opt"])
        if self.normalizer is not None:
            sb3.load_normalizer_state(self.normalizer, state["normalizer"])
        self.discriminator.load_state_dict(state["discriminator"])
        self.d_opt.load_state_dict(state["d_opt"])
        self.rng.bit_generator.state = state["rng"]
