"""LAPO's options (:class:`LAPOOptions`) and their defaults per env kind.

Each option is a flag of its own, prefixed ``lapo-`` (``--lapo-model-steps``, ...), and a key of
``--method-options``. The bottleneck and the losses' weights are the authors' code's
(github.com/schmidtdominik/LAPO, ``config.yaml``, ``lapo/models.py``); the step counts are
cut to this project's CPU budget (:data:`OPTION_DEFAULTS` says how).

Importing this module imports no torch.

Example:
    >>> from abco_train.config.run import RunConfig
    >>> options = LAPOOptions.for_run(RunConfig(env="CartPole-v1"))
    >>> options.codebooks, options.slots, options.code_dim, options.codes, options.latent_dim
    (2, 4, 16, 64, 128)
    >>> LAPOOptions.for_run(RunConfig(env="CartPole-v1", method_options={"codes": 1}))
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: --lapo-codes must be >= 2, got 1
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from abco_train.config.fields import MethodOptions, Search, option
from abco_train.config.limits import (
    MAX_EPOCHS,
    MAX_ITERATIONS,
    MAX_LATENTS,
    MAX_STEPS,
    MAX_WIDTH,
)
from abco_train.config.run import RunConfig, env_kind
from abco_train.methods.converged import CONVERGED_DEFAULTS, converged_option, schedule_option

__all__ = ["LAPOOptions", "OPTION_DEFAULTS"]


@dataclass
class LAPOOptions(MethodOptions):
    """LAPO's settings (:mod:`abco_train.methods.lapo.method` maps them to the paper)."""

    run_search: ClassVar[tuple[str, ...]] = ()  # its learning rates are options of its own

    flag_prefix: ClassVar[str] = "lapo-"

    rounds: int = option("training rounds, each evaluated: stage 2's steps are spread evenly "
                         "over them", min=1, max=MAX_ITERATIONS)  # fmt: skip
    codebooks: int = option("vector-quantisation codebooks", min=1, max=MAX_LATENTS)
    slots: int = option("latent vectors quantised per codebook", min=1, max=MAX_LATENTS)
    code_dim: int = option("width of a latent vector and of its codes", min=1, max=MAX_WIDTH)
    codes: int = option("codes per codebook", min=2, max=MAX_LATENTS)
    commitment: float = option("weight of the commitment loss |z - sg(q)|^2", min=0.0,
                               search=Search(0.01, 0.5, log=True))
    ema_decay: float = option("decay of the codebooks' moving averages", min=0.0, max=1.0)
    hidden: int = option("hidden units of the forward model's and the decoder's MLPs",
                         min=1, max=MAX_WIDTH)  # fmt: skip
    pool: int = option("frames: average-pool the forward model's target s' - s by this factor",
                       min=1, max=MAX_WIDTH)  # fmt: skip
    model_steps: int = option("Adam steps of the latent IDM and the forward model (stage 1, "
                              "in the first iteration)", min=0, max=MAX_STEPS)  # fmt: skip
    model_lr: float = option("Adam's learning rate of stage 1", min=0.0, exclusive=True,
                             search=Search(1e-4, 1e-3, log=True))
    grad_clip: float = option("stage 1's gradient-norm clip", min=0.0, exclusive=True)
    policy_steps: int = option("Adam steps of the latent policy (stage 2), spread evenly over "
                               "the rounds", min=0, max=MAX_STEPS)  # fmt: skip
    policy_lr: float = option("Adam's learning rate of stage 2", min=0.0, exclusive=True,
                              search=Search(5e-5, 1e-3, log=True))
    decoder_epochs: int = option("epochs of the latent -> action decoder over the "
                                 "pre-demonstrations (stage 3, offline)", min=0,
                                 max=MAX_EPOCHS)  # fmt: skip
    label_smoothing: float = option("label smoothing of the decoder's cross-entropy",
                                    min=0.0, max=1.0)  # fmt: skip
    schedule: str = schedule_option("steps", "model-steps, decoder-epochs, policy-steps")
    check_updates: int = converged_option("check_updates")
    patience_checks: int = converged_option("patience_checks")
    min_fit_updates: int = converged_option("min_fit_updates")
    max_fit_updates: int = converged_option("max_fit_updates")

    @property
    def latent_dim(self) -> int:
        """The latent's width: ``codebooks * slots * code_dim``."""
        return self.codebooks * self.slots * self.code_dim

    @classmethod
    def for_run(cls, config: RunConfig, method: str = "lapo") -> LAPOOptions:
        """The options of ``config``'s run: its ``method_options`` over its env kind's.

        Raises:
            ConfigError: An unknown option or a value out of range.
        """
        return cls.resolve(config.method_options, OPTION_DEFAULTS[env_kind(config.env)],
                           method)  # fmt: skip


#: The authors' values: 2 codebooks of 64 codes, 4 slots of 16 each (a 128-wide latent),
#: commitment 0.05, EMA decay 0.999, stage 1 at 3e-4 with gradients clipped at 2, stage 2 at
#: 2e-4, the decoder 3 epochs with label smoothing 0.05. Their stages take 50,000 and 60,000
#: steps of 128 (about a GPU-hour each); here classic control takes 4,000 and 2,000 of the
#: run's ``--batch-size``, frames 1,500 and 1,000 (the run's networks on a CPU). With
#: ``schedule="converged"`` the counts give way to each stage's held-out score
#: (:mod:`abco_train.methods.lapo.method`).
_CLASSIC: dict[str, Any] = {
    "rounds": 3, "codebooks": 2, "slots": 4, "code_dim": 16, "codes": 64, "commitment": 0.05,
    "ema_decay": 0.999, "hidden": 64, "pool": 4, "model_steps": 4000, "model_lr": 3e-4,
    "grad_clip": 2.0, "policy_steps": 2000, "policy_lr": 2e-4, "decoder_epochs": 3,
    "label_smoothing": 0.05, "schedule": "steps", **CONVERGED_DEFAULTS,
}  # fmt: skip
OPTION_DEFAULTS: dict[str, dict[str, Any]] = {
    # Vector tasks train each stage to convergence: on the headline's four classic tasks,
    # validation seeds 100-102, it scored higher or equal on every task once scores below
    # random count as random (Acrobot 0.204 -> 0.301, CartPole 0.909 -> 1.000, MountainCar
    # 0.000 -> 0.008, LunarLander 0 both; docs/notes/fair-fight.md).
    "classic": {**_CLASSIC, "schedule": "converged"},
    "maze": {**_CLASSIC, "model_steps": 1500, "policy_steps": 1000},
    "image": {**_CLASSIC, "model_steps": 1500, "policy_steps": 1000, "pool": 1},
}
