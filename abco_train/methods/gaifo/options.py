"""GAIfO's options (:class:`GAIfOOptions`) and their defaults per env kind and environment.

Each option is a command-line flag of its own, prefixed ``gaifo-`` (``abco train --method gaifo
--help``: ``--gaifo-rl-steps``, ``--gaifo-batch-size``, ...; the prefix keeps them apart from
the run config's ``--batch-size`` and ``--lr``) and a key of ``--method-options``. Options not
given take :data:`COMMON_OPTIONS`, then the run's env kind's and environment's changes
(:data:`GAIFO_DEFAULTS`); the user's values win.

Importing this module imports neither torch nor stable-baselines3.

Example:
    >>> from abco_train.config.run import RunConfig
    >>> GAIfOOptions.for_run(RunConfig(env="CartPole-v1")).reward
    'gail'
    >>> GAIfOOptions.for_run(RunConfig(env="CartPole-v1", method_options={"n_steps": 0}))
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: --gaifo-n-steps must be >= 1, got 0
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import abco_envs
from abco_train.config.fields import ConfigError, MethodOptions, flag_of, option
from abco_train.config.limits import MAX_ENVS, MAX_EPOCHS, MAX_STEPS, MAX_WIDTH
from abco_train.config.run import RunConfig, env_kind

__all__ = ["GAIfOOptions", "REWARDS", "COMMON_OPTIONS", "GAIFO_DEFAULTS"]

#: How the learner's reward is computed from the discriminator's logit
#: (:func:`abco_train.methods.gaifo.method.reward_from_logits`).
REWARDS = ("logit", "gail", "log_d")


@dataclass
class GAIfOOptions(MethodOptions):
    """GAIfO's PPO learner and discriminator; an option left ``None`` takes the run's
    default (:meth:`for_run`), so that none is ``None`` once resolved."""

    flag_prefix: ClassVar[str] = "gaifo-"

    rl_steps: int = option("PPO env steps per run (the budget), split into rounds",
                           min=1, max=MAX_STEPS)
    n_envs: int = option("parallel envs of PPO's rollouts", min=1, max=MAX_ENVS)
    n_steps: int = option("steps per env per rollout: a round is n_steps * n_envs",
                          min=1, max=MAX_STEPS)
    batch_size: int = option("PPO minibatch", min=1, max=MAX_STEPS)
    n_epochs: int = option("PPO epochs per rollout", min=1, max=MAX_EPOCHS)
    learning_rate: float = option("PPO's learning rate (Adam)", min=0.0, exclusive=True)
    gamma: float = option("PPO's discount factor", min=0.0, max=1.0)
    gae_lambda: float = option("PPO's GAE lambda", min=0.0, max=1.0)
    clip_range: float = option("PPO's clip range", min=0.0, exclusive=True)
    ent_coef: float = option("PPO's entropy coefficient", min=0.0)
    vf_coef: float = option("PPO's value-loss coefficient", min=0.0)
    max_grad_norm: float = option("PPO's gradient-norm clip", min=0.0, exclusive=True)
    net_arch: list[int] = option("widths of PPO's policy and value MLPs (after the CNN for "
                                 "frames), e.g. [64, 64]")  # fmt: skip
    features_dim: int = option("frames: width of the policy CNN's output", min=1, max=MAX_WIDTH)
    reward: str = option("the learner's reward from the discriminator's logit l: logit (l), "
                         "gail (-log(1 - D)) or log_d (log D)", choices=REWARDS)  # fmt: skip
    reward_clip: float = option("rewards are clipped to [-reward_clip, reward_clip]", min=0.0,
                                exclusive=True)  # fmt: skip
    d_lr: float = option("the discriminator's learning rate (Adam)", min=0.0, exclusive=True)
    d_epochs: int = option("discriminator passes over each round's learner pairs",
                           min=1, max=MAX_EPOCHS)
    d_batch_size: int = option("learner pairs per discriminator minibatch (plus as many expert "
                               "pairs)", min=1, max=MAX_STEPS)  # fmt: skip
    d_hidden: int = option("vectors: width of the discriminator MLP", min=1, max=MAX_WIDTH)

    @classmethod
    def for_run(cls, config: RunConfig, method: str = "gaifo") -> GAIfOOptions:
        """The options of ``config``'s run: its ``method_options`` over :data:`COMMON_OPTIONS`,
        then the env kind's and then the environment's :data:`GAIFO_DEFAULTS`.

        Raises:
            ConfigError: An unknown option or a value that does not fit (the message names it).
        """
        defaults = {**COMMON_OPTIONS, **GAIFO_DEFAULTS[env_kind(config.env)],
                    **GAIFO_DEFAULTS.get(abco_envs.env_name(config.env), {})}  # fmt: skip
        given = config.method_options
        options = cls.resolve(given, copy.deepcopy(defaults), method)
        options.check()
        return options

    def check(self) -> None:
        """The checks the fields' own cannot make: every option set, ``net_arch`` a list of
        widths.

        Raises:
            ConfigError: The first that fails, named as its command-line option.
        """
        for f in fields(self):
            if getattr(self, f.name) is None:
                raise ConfigError(f"{flag_of(f.name, self.flag_prefix)} must be set, got null")
        arch = self.net_arch
        if not isinstance(arch, (list, tuple)) or not all(
            isinstance(w, int) and not isinstance(w, bool) and w >= 1 for w in arch
        ):
            raise ConfigError(f"{flag_of('net_arch', self.flag_prefix)} must be a list of "
                              f"integers >= 1, got {arch!r}")  # fmt: skip


#: Options of every run; :data:`GAIFO_DEFAULTS` changes them per env kind and environment.
COMMON_OPTIONS: dict[str, Any] = {
    "rl_steps": 150_000,      # PPO env steps per run (the budget), split into rounds
    "n_envs": 16,             # parallel envs of PPO's rollouts
    "n_steps": 128,           # steps per env per rollout: a round is n_steps * n_envs
    "batch_size": 64,         # PPO minibatch
    "n_epochs": 4,            # PPO epochs per rollout
    "learning_rate": 3e-4,    # PPO (Adam)
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 0.0,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "net_arch": [64, 64],     # PPO's policy and value MLPs (after the CNN for frames)
    "features_dim": 256,      # frames: width of the policy CNN's output
    "reward": "logit",        # one of REWARDS
    "reward_clip": 10.0,
    "d_lr": 3e-4,             # discriminator (Adam)
    "d_epochs": 1,            # passes over each round's learner pairs
    "d_batch_size": 256,      # learner pairs per D minibatch (plus as many expert pairs)
    "d_hidden": 64,           # vectors: width of the discriminator MLP
}  # fmt: skip

#: Per env kind, then per environment, on top of :data:`COMMON_OPTIONS`, chosen on seeds
#: 100-102 (CartPole's reward: see :mod:`abco_train.methods.gaifo.method`; docs/training.md
#: has the numbers).
GAIFO_DEFAULTS: dict[str, dict[str, Any]] = {
    "classic": {},
    "maze": {"rl_steps": 60_000, "n_steps": 64},
    "CartPole-v1": {"rl_steps": 50_000, "reward": "gail"},
    "Acrobot-v1": {},
    "MountainCar-v0": {},
    "AbcoMaze3x3-v0": {},
    "AbcoMaze5x5-v0": {},
    "AbcoMaze10x10-v0": {},
}  # fmt: skip
