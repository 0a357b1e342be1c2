"""ILPO's options (:class:`ILPOOptions`), their defaults and their checks.

Each option is a command-line flag of its own (``abco train --method ilpo --help``:
``--ilpo-latents``, ``--ilpo-train-steps``, ...) and a key of ``--method-options``. ``None``
options take the defaults of the run's env kind (:data:`OPTION_DEFAULTS`), then its
environment's (:data:`ENV_OPTION_DEFAULTS`); the user's values win. Then ``latents`` ``None`` is
the env's number of actions and, on a maze, ``remap_max_steps`` ``None`` is ``4 n^2``.

Importing this module imports no torch.

Example:
    >>> from abco_train.config.run import RunConfig
    >>> options = ILPOOptions.for_run(RunConfig(env="AbcoMaze5x5-v0"))
    >>> options.latents, options.pool, options.policy_steps, options.remap_max_steps
    (4, 8, 1000, 100)
    >>> ILPOOptions.for_run(RunConfig(env="CartPole-v1", method_options={"latents": 1}))
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: --ilpo-latents must be >= 2, got 1
"""

from __future__ import annotations

import typing
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import abco_envs
from abco_data.registry import ACTION_COUNTS
from abco_train.config.envs import env_spaces
from abco_train.config.fields import ConfigError, MethodOptions, Search, flag_of, option
from abco_train.config.limits import MAX_ENVS, MAX_EPOCHS, MAX_LATENTS, MAX_STEPS, MAX_WIDTH
from abco_train.config.run import CELL_ARCHS, RunConfig, env_kind
from abco_train.methods.converged import CONVERGED_DEFAULTS, converged_option, schedule_option

__all__ = ["ILPOOptions", "OPTION_DEFAULTS", "ENV_OPTION_DEFAULTS", "TARGETS", "LATENT_INITS",
           "REMAP_MODES", "REMAP_INPUTS"]  # fmt: skip

#: What ``G`` predicts on frames: the pooled difference image, or each maze cell's change.
TARGETS = ("pooled", "cells")
#: How the latent embeddings start: drawn apart, or one embedding plus ``split_noise``.
LATENT_INITS = ("random", "shared")
#: How a latent becomes an action: a classifier ``P(a | s, z)`` or a count table ``P(a | z)``.
REMAP_MODES = ("state", "table")
#: What the remapping classifier reads besides ``onehot(z)``.
REMAP_INPUTS = ("effect+embedding", "effect", "embedding")


@dataclass
class ILPOOptions(MethodOptions):
    """ILPO's settings (:mod:`abco_train.methods.ilpo.method` maps them to the paper); ``None``:
    the run's default."""

    flag_prefix: ClassVar[str] = "ilpo-"

    latents: int | None = option("k, the number of latent actions (default: the env's number "
                                 "of actions)", min=2, max=MAX_LATENTS)  # fmt: skip
    train_steps: int = option("Adam steps of G and pi on the expert pairs in iteration 0",
                              min=0, max=MAX_STEPS,
                              search=Search(500, 6000, log=True,
                                            read_when=(("schedule", "steps"),)))  # fmt: skip
    policy_steps: int | None = option("train G alone for --ilpo-train-steps steps, then pi alone "
                                      "for this many steps against the fixed G; null: train "
                                      "them together (default: 1000 on mazes, null on classic "
                                      "control)", min=1, max=MAX_STEPS)  # fmt: skip
    later_steps: int = option("steps of G and pi in every later iteration", min=0, max=MAX_STEPS)
    hidden: int = option("hidden units of the latent policy and the vector forward model",
                         min=1, max=MAX_WIDTH)  # fmt: skip
    channels: int = option("channels of the convolutional forward model (frames)",
                           min=1, max=MAX_WIDTH)
    pool: int = option("frames: average-pool the difference image by this factor",
                       min=1, max=MAX_WIDTH)
    target: str | None = option("what G predicts on frames: pooled (the pooled difference "
                                "image) or cells (how much each maze cell changed; mazes "
                                "only). Default: cells where the run's encoder reads the maze "
                                "cell by cell (--arch cellnet/cellplan), else pooled: ILPO "
                                "sees the maze's cells where every method does",
                                choices=TARGETS)  # fmt: skip
    exp_weight: float = option("fraction of L_exp's gradient that reaches G (joint schedule "
                               "only)", min=0.0, max=1.0,
                               search=Search(0.0, 1.0, read_when=(("policy_steps", None),)))
    relax: float = option("relaxed winner-takes-all: L_min plus relax * mean_z ||.||^2",
                          min=0.0, max=1.0, search=Search(0.01, 0.5, log=True))  # fmt: skip
    latent_init: str = option("latent embeddings start random, or shared (one embedding plus "
                              "--ilpo-split-noise)", choices=LATENT_INITS)  # fmt: skip
    split_noise: float = option("noise that splits the shared latent embedding",
                                min=0.0, max=1.0)  # fmt: skip
    remap: str = option("action remapping: state (a classifier P(a | s, z)) or table (counts "
                        "P(a | z))", choices=REMAP_MODES,
                        search=Search(choices=REMAP_MODES))  # fmt: skip
    remap_input: str = option("what the remapping classifier reads besides onehot(z): "
                              "effect (what z does in s), embedding (E(s)) or both",
                              choices=REMAP_INPUTS)  # fmt: skip
    remap_steps: int = option("environment steps of remapping per iteration (counted)",
                              min=0, max=MAX_STEPS)
    remap_envs: int = option("parallel environments of the remapping steps", min=1, max=MAX_ENVS)
    remap_epsilon: float = option("epsilon of the epsilon-greedy remapping steps after the "
                                  "first iteration's random ones", min=0.0, max=1.0)  # fmt: skip
    remap_margin: float = option("keep a remapping step only if its best latent's error is "
                                 "below this fraction of the second best's", min=0.0,
                                 exclusive=True, max=1.0)  # fmt: skip
    remap_epochs: int = option("epochs of the remapping classifier over the kept steps per "
                               "iteration", min=0, max=MAX_EPOCHS)  # fmt: skip
    remap_max_steps: int | None = option("mazes: cut remapping episodes after this many steps "
                                         "(default: 4 n^2)", min=1, max=MAX_STEPS)  # fmt: skip
    schedule: str = schedule_option("steps", "train-steps, policy-steps, later-steps; the "
                                    "remapping keeps its epochs")  # fmt: skip
    check_updates: int = converged_option("check_updates")
    patience_checks: int = converged_option("patience_checks")
    min_fit_updates: int = converged_option("min_fit_updates")
    max_fit_updates: int = converged_option("max_fit_updates")

    @classmethod
    def for_run(cls, config: RunConfig, method: str = "ilpo") -> ILPOOptions:
        """The options of ``config``'s run: its ``method_options`` over the defaults.

        Raises:
            ConfigError: An unknown option, a value out of range, or options that do not fit
                the run (``target`` ``cells`` off the mazes).
        """
        name, kind = abco_envs.env_name(config.env), env_kind(config.env)
        defaults = {**OPTION_DEFAULTS[kind], **ENV_OPTION_DEFAULTS.get(name, {})}
        options = cls.resolve(config.method_options, defaults, method)
        options.check(config)
        if options.target is None:  # the cell prior where the run's encoder has it, only
            options.target = "cells" if kind == "maze" and config.arch in CELL_ARCHS else "pooled"
        if options.latents is None:  # the env's actions (another env's: read from it)
            options.latents = ACTION_COUNTS.get(name) or env_spaces(config.env).n_actions
        if options.remap_max_steps is None and kind == "maze":
            n = abco_envs.maze_size(config.env)
            options.remap_max_steps = 4 * n * n
        return options

    def check(self, config: RunConfig) -> None:
        """The checks beyond each value's own: set where ``None`` means nothing, and between
        options and the run's env.

        Raises:
            ConfigError: The first that fails, naming the option.
        """
        hints = typing.get_type_hints(type(self))
        for f in fields(self):
            if getattr(self, f.name) is None and type(None) not in typing.get_args(hints[f.name]):
                raise ConfigError(f"{flag_of(f.name, self.flag_prefix)} must be set, got null")
        if self.target == "cells" and env_kind(config.env) != "maze":
            raise ConfigError("--ilpo-target cells is for maze frames (one value per cell); "
                              "classic control takes --ilpo-target pooled")  # fmt: skip


#: ILPO's options by env kind (``None``: decided from the env, see :meth:`ILPOOptions.for_run`).
#: Classic control keeps only the remapping steps whose best latent explains them 10 times
#: better than the second best (``remap_margin`` 0.1, was 0.5): on Acrobot the latent model
#: tells the torques apart in ~99% of the expert's states, but the steps it explains only 2-10
#: times better than the next latent are noisy labels, and the remapping, not the model, was
#: what lost accuracy (docs/training.md, validation seeds 100-102). Mazes train ``pi`` after
#: ``G`` (``policy_steps`` 1000; :mod:`abco_train.methods.ilpo.method`): trained together,
#: ``pi`` saturated on one latent in most 5x5 seeds (docs/training.md, validation seeds
#: 100-107).
_CLASSIC_DEFAULTS: dict[str, Any] = {
    "latents": None, "train_steps": 3000, "policy_steps": None, "later_steps": 0,
    "hidden": 64, "channels": 16, "pool": 1, "target": None, "exp_weight": 0.0,
    "relax": 0.0, "latent_init": "random", "split_noise": 0.01, "remap": "state",
    "remap_input": "effect+embedding", "remap_steps": 500, "remap_envs": 10,
    "remap_epsilon": 0.2, "remap_margin": 0.1, "remap_epochs": 20, "remap_max_steps": None,
    "schedule": "steps", **CONVERGED_DEFAULTS,
}  # fmt: skip
OPTION_DEFAULTS: dict[str, dict[str, Any]] = {
    # Vector tasks train G and pi to convergence: on the headline's four classic tasks,
    # validation seeds 100-102, the mean score went 0.760 -> 0.788 at the same cell time
    # (LunarLander 0.216 -> 0.330, the others within 0.003; docs/notes/fair-fight.md).
    "classic": {**_CLASSIC_DEFAULTS, "schedule": "converged"},
    "maze": {**_CLASSIC_DEFAULTS, "train_steps": 1300, "policy_steps": 1000, "hidden": 128,
             "pool": 4, "remap_steps": 1000, "remap_envs": 50, "remap_margin": 0.5},
}  # fmt: skip
# Other image envs (any size: MiniGrid's 7x7 view has no pixels to pool): the mazes' settings,
# the frames unpooled.
OPTION_DEFAULTS["image"] = {**OPTION_DEFAULTS["maze"], "pool": 1}

#: Per-environment changes on top of :data:`OPTION_DEFAULTS`.
ENV_OPTION_DEFAULTS: dict[str, dict[str, Any]] = {
    # Acrobot remaps from 1,000 steps a round (31 rounds at its alpha = 30: 31,000 steps):
    # validation seeds 100-115, mean AER -78.4 against -87.2 with 500 (docs/training.md).
    "Acrobot-v1": {"remap_steps": 1000},
    # Pooled frames keep at least ~1.6 pixels per cell: 8x8 maps up to 5x5, 16x16 for 10x10.
    "AbcoMaze3x3-v0": {"pool": 8},
    "AbcoMaze5x5-v0": {"pool": 8},
    # 10x10 (docs/notes/ilpo-tuning.md, "ILPO on the 10x10 maze"): chosen with the cell
    # target (``--ilpo-target cells``, a local G), whose latents mean one move everywhere and
    # a table maps them. The target itself follows the run's encoder (``target`` above).
    "AbcoMaze10x10-v0": {"pool": 4, "relax": 0.05, "remap": "table", "policy_steps": 10000},
}
