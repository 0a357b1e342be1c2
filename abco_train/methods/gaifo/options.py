"""GAIfO's options (:class:`GAIfOOptions`) and their defaults per environment family.

Each option is a command-line flag of its own, prefixed ``gaifo-`` (``abco train --method gaifo
--help``: ``--gaifo-rl-steps``, ``--gaifo-batch-size``, ...; the prefix keeps them apart from
the run config's ``--batch-size`` and ``--lr``) and a key of ``--method-options``. Options not
given take :data:`COMMON_OPTIONS`, then the environment family's published PPO settings
(:data:`ZOO_PPO`), then GAIfO's own changes per env kind and environment
(:data:`GAIFO_DEFAULTS`); the user's values win.

Importing this module imports neither torch nor stable-baselines3.

Example:
    >>> from abco_train.config.run import RunConfig
    >>> options = GAIfOOptions.for_run(RunConfig(env="CartPole-v1"))
    >>> options.reward, options.n_envs, options.n_steps, options.learning_rate_schedule
    ('gail', 8, 32, 'linear')
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
from abco_train.config.fields import ConfigError, MethodOptions, Search, flag_of, option
from abco_train.config.limits import MAX_ENVS, MAX_EPOCHS, MAX_STEPS, MAX_WIDTH
from abco_train.config.run import RunConfig, env_kind

__all__ = ["GAIfOOptions", "REWARDS", "SCHEDULES", "COMMON_OPTIONS", "ZOO_PPO",
           "GAIFO_DEFAULTS", "ppo_family"]  # fmt: skip

#: How the learner's reward is computed from the discriminator's logit
#: (:func:`abco_train.methods.gaifo.method.reward_from_logits`).
REWARDS = ("logit", "gail", "log_d")
#: How PPO's learning rate and clip range change over the run's PPO steps: ``constant``, or
#: ``linear`` from the value given down to 0 (the Zoo's ``lin_`` values).
SCHEDULES = ("constant", "linear")


@dataclass
class GAIfOOptions(MethodOptions):
    """GAIfO's PPO learner and discriminator; an option left ``None`` takes the run's
    default (:meth:`for_run`), so that none is ``None`` once resolved."""

    run_search: ClassVar[tuple[str, ...]] = ()  # its learning rates are options of its own

    flag_prefix: ClassVar[str] = "gaifo-"

    rl_steps: int = option("most PPO env steps per run, split into rollouts (whole rollouts "
                           "only; the run's --budget caps them too)",
                           min=1, max=MAX_STEPS)  # fmt: skip
    n_envs: int = option("parallel envs of PPO's rollouts", min=1, max=MAX_ENVS)
    n_steps: int = option("steps per env per rollout: a round is n_steps * n_envs",
                          min=1, max=MAX_STEPS)
    batch_size: int = option("PPO minibatch", min=1, max=MAX_STEPS)
    n_epochs: int = option("PPO epochs per rollout", min=1, max=MAX_EPOCHS, search=Search(3, 20))
    learning_rate: float = option("PPO's learning rate (Adam; the start value if linear)",
                                  min=0.0, exclusive=True, search=Search(5e-5, 3e-3, log=True)
                                  )  # fmt: skip
    learning_rate_schedule: str = option("PPO's learning rate over the run's PPO steps: "
                                         "constant, or linear down to 0", choices=SCHEDULES)
    gamma: float = option("PPO's discount factor", min=0.0, max=1.0)
    gae_lambda: float = option("PPO's GAE lambda", min=0.0, max=1.0)
    clip_range: float = option("PPO's clip range (the start value if linear)", min=0.0,
                               exclusive=True)  # fmt: skip
    clip_range_schedule: str = option("PPO's clip range over the run's PPO steps: constant, "
                                      "or linear down to 0", choices=SCHEDULES)  # fmt: skip
    ent_coef: float = option("PPO's entropy coefficient", min=0.0,
                             search=Search(1e-4, 0.05, log=True))
    vf_coef: float = option("PPO's value-loss coefficient", min=0.0)
    max_grad_norm: float = option("PPO's gradient-norm clip", min=0.0, exclusive=True)
    normalize: bool = option("stable-baselines3's VecNormalize between the env and PPO: "
                             "running standardisation of vector observations and scaling of "
                             "the learner's rewards (frames: rewards only)")  # fmt: skip
    net_arch: list[int] = option("widths of PPO's policy and value MLPs (after the CNN for "
                                 "frames), e.g. [64, 64]")  # fmt: skip
    features_dim: int = option("frames: width of the policy CNN's output", min=1, max=MAX_WIDTH)
    reward: str = option("the learner's reward from the discriminator's logit l: logit (l), "
                         "gail (-log(1 - D)) or log_d (log D)", choices=REWARDS)  # fmt: skip
    reward_clip: float = option("rewards are clipped to [-reward_clip, reward_clip]", min=0.0,
                                exclusive=True)  # fmt: skip
    d_lr: float = option("the discriminator's learning rate (Adam)", min=0.0, exclusive=True,
                         search=Search(3e-5, 3e-3, log=True))
    d_epochs: int = option("discriminator passes over each round's learner pairs",
                           min=1, max=MAX_EPOCHS)
    d_batch_size: int = option("learner pairs per discriminator minibatch (plus as many expert "
                               "pairs)", min=1, max=MAX_STEPS)  # fmt: skip
    d_hidden: int = option("vectors: width of the discriminator MLP", min=1, max=MAX_WIDTH)

    @classmethod
    def for_run(cls, config: RunConfig, method: str = "gaifo") -> GAIfOOptions:
        """The options of ``config``'s run: its ``method_options`` over :data:`COMMON_OPTIONS`,
        the environment family's :data:`ZOO_PPO` row, then the env kind's and then the
        environment's :data:`GAIFO_DEFAULTS`.

        Raises:
            ConfigError: An unknown option or a value that does not fit (the message names it).
        """
        name = abco_envs.env_name(config.env)
        defaults = {**COMMON_OPTIONS, **ZOO_PPO.get(ppo_family(config.env), {}),
                    **GAIFO_DEFAULTS.get(env_kind(config.env), {}),
                    **GAIFO_DEFAULTS.get(name, {})}  # fmt: skip
        given = config.method_options
        options = cls.resolve(given, copy.deepcopy(defaults), method)
        options.check()
        return options

    @property
    def rollout_steps(self) -> int:
        """Env steps of one PPO rollout (a round): ``n_steps * n_envs``."""
        return self.n_steps * self.n_envs

    def check(self) -> None:
        """The checks the fields' own cannot make: every option set, ``net_arch`` a list of
        widths, ``rl_steps`` at least one rollout.

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
        if self.rl_steps < self.rollout_steps:
            steps, n_steps, n_envs = (flag_of(name, self.flag_prefix)
                                      for name in ("rl_steps", "n_steps", "n_envs"))
            raise ConfigError(f"{steps} must be at least one PPO rollout ({n_steps} x "
                              f"{n_envs} = {self.rollout_steps:,}), got "
                              f"{self.rl_steps:,}")  # fmt: skip


def ppo_family(env_id: str) -> str:
    """The key of ``env_id``'s row in :data:`ZOO_PPO`: ``"maze"`` for every abco maze, the
    environment's name (without a module prefix) otherwise.

    Example:
        >>> ppo_family("abco_envs:AbcoMaze5x5-v0"), ppo_family("Acrobot-v1")
        ('maze', 'Acrobot-v1')
    """
    return "maze" if abco_envs.is_maze(env_id) else abco_envs.env_name(env_id)


#: Options of every run, under the env family's :data:`ZOO_PPO` row: PPO's are
#: stable-baselines3's own ``PPO()`` defaults (and the Zoo's default of one env), which the
#: Zoo's rows leave in place wherever they name no value.
COMMON_OPTIONS: dict[str, Any] = {
    "rl_steps": 150_000,      # most PPO env steps per run (whole rollouts; --budget caps too)
    "n_envs": 1,              # parallel envs of PPO's rollouts
    "n_steps": 2048,          # steps per env per rollout: a round is n_steps * n_envs
    "batch_size": 64,         # PPO minibatch
    "n_epochs": 10,           # PPO epochs per rollout
    "learning_rate": 3e-4,    # PPO (Adam)
    "learning_rate_schedule": "constant",
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "clip_range_schedule": "constant",
    "ent_coef": 0.0,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "normalize": False,       # VecNormalize
    "net_arch": [64, 64],     # PPO's policy and value MLPs (after the CNN for frames)
    "features_dim": 256,      # frames: width of the policy CNN's output
    "reward": "logit",        # one of REWARDS
    "reward_clip": 10.0,
    "d_lr": 3e-4,             # discriminator (Adam)
    "d_epochs": 1,            # passes over each round's learner pairs
    "d_batch_size": 256,      # learner pairs per D minibatch (plus as many expert pairs)
    "d_hidden": 64,           # vectors: width of the discriminator MLP
}  # fmt: skip

#: The RL Baselines3 Zoo's published PPO hyperparameters per environment family (key:
#: :func:`ppo_family`), from ``hyperparams/ppo.yml`` of DLR-RM/rl-baselines3-zoo (commit
#: 208b6fd), every setting but ``n_timesteps`` (``rl_steps`` and the run's ``--budget``
#: set the steps) and ``policy`` (MlpPolicy for vectors; frames get a CNN). How they carry
#: over:
#:
#: * ``lin_X`` (a linear schedule from ``X`` at the start to 0 at the end of training):
#:   value ``X`` and schedule ``linear``, over the run's planned PPO steps (not one
#:   ``learn()`` call's: GAIfO calls it once per rollout).
#: * ``normalize: true`` is SB3's ``VecNormalize`` (observations and rewards, ``gamma`` =
#:   PPO's, as the Zoo passes it), placed between the discriminator's reward and PPO: ``D``
#:   sees raw observations, PPO standardised ones and the rewards scaled. Frames keep SB3's
#:   scaling to [0, 1] (running per-pixel statistics are not what a CNN policy expects; the
#:   Zoo's MiniGrid observations were flat symbolic vectors), so there ``normalize`` scales
#:   the rewards only.
#: * No row sets ``policy_kwargs``: SB3's default MLP (64-64, tanh, orthogonal init) is the
#:   Zoo's, hence ``net_arch`` [64, 64] in :data:`COMMON_OPTIONS`.
#: * Settings a row leaves out are SB3's ``PPO()`` defaults (:data:`COMMON_OPTIONS`).
ZOO_PPO: dict[str, dict[str, Any]] = {
    # ppo.yml "CartPole-v1" (marked "Tuned"); learning_rate lin_0.001, clip_range lin_0.2
    "CartPole-v1": {"n_envs": 8, "n_steps": 32, "batch_size": 256, "gae_lambda": 0.8,
                    "gamma": 0.98, "n_epochs": 20, "ent_coef": 0.0, "learning_rate": 1e-3,
                    "learning_rate_schedule": "linear", "clip_range": 0.2,
                    "clip_range_schedule": "linear"},
    # ppo.yml "Acrobot-v1"
    "Acrobot-v1": {"normalize": True, "n_envs": 16, "n_steps": 256, "gae_lambda": 0.94,
                   "gamma": 0.99, "n_epochs": 4, "ent_coef": 0.0},
    # ppo.yml "MountainCar-v0"
    "MountainCar-v0": {"normalize": True, "n_envs": 16, "n_steps": 16, "gae_lambda": 0.98,
                       "gamma": 0.99, "n_epochs": 4, "ent_coef": 0.0},
    # ppo.yml "LunarLander-v2" (gymnasium 1's LunarLander-v3 is the same task)
    "LunarLander-v3": {"n_envs": 16, "n_steps": 1024, "batch_size": 64, "gae_lambda": 0.98,
                       "gamma": 0.999, "n_epochs": 4, "ent_coef": 0.01},
    # ppo.yml "MiniGrid-Empty-Random-5x5-v0" (&minigrid-defaults, shared by the Zoo's
    # MiniGrid rows but FourRooms' and RedBlueDoors' n_steps 512): small grid worlds
    "maze": {"normalize": True, "n_envs": 8, "n_steps": 128, "batch_size": 64,
             "gae_lambda": 0.95, "gamma": 0.99, "n_epochs": 10, "ent_coef": 0.0,
             "learning_rate": 2.5e-4, "clip_range": 0.2},
}  # fmt: skip

#: GAIfO's own changes per env kind, then per environment, on top of :data:`ZOO_PPO`: the
#: steps a run may take without a ``--budget`` and the reward's form (CartPole's: see
#: :mod:`abco_train.methods.gaifo.method`; docs/training.md has the numbers).
GAIFO_DEFAULTS: dict[str, dict[str, Any]] = {
    "classic": {},
    "maze": {"rl_steps": 60_000},
    "CartPole-v1": {"rl_steps": 50_000, "reward": "gail"},
}  # fmt: skip
