"""DILO's options (:class:`DILOOptions`) and their defaults per env kind.

Each option is a flag of its own, prefixed ``dilo-`` (``--dilo-steps``, ``--dilo-beta``, ...),
and a key of ``--method-options``. The defaults are the authors' code's (github.com/hari-sikchi/
DILO, ``dilo.py`` and ``train_dilo.py``) but for the number of gradient steps and the learning
rates, which are the run's (:data:`OPTION_DEFAULTS` says why).

Importing this module imports no torch.

Example:
    >>> from abco_train.config.run import RunConfig
    >>> options = DILOOptions.for_run(RunConfig(env="CartPole-v1"))
    >>> options.steps, options.beta, options.temperature, options.weight_clip
    (5000, 0.5, 0.06, 100.0)
    >>> DILOOptions.for_run(RunConfig(env="CartPole-v1", method_options={"gamma": 1.5}))
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: --dilo-gamma must be <= 1.0, got 1.5
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from abco_train.config.fields import MethodOptions, Search, option
from abco_train.config.limits import MAX_ITERATIONS, MAX_STEPS
from abco_train.config.run import RunConfig, env_kind
from abco_train.methods.converged import CONVERGED_DEFAULTS, converged_option, schedule_option

__all__ = ["DILOOptions", "OPTION_DEFAULTS"]


@dataclass
class DILOOptions(MethodOptions):
    """DILO's settings (:mod:`abco_train.methods.dilo.method` maps them to the paper)."""

    flag_prefix: ClassVar[str] = "dilo-"

    rounds: int = option("training rounds, each evaluated: the steps are spread evenly over "
                         "them", min=1, max=MAX_ITERATIONS)  # fmt: skip
    steps: int = option("gradient steps of the utility V(s, s') and the policy, spread evenly "
                        "over the rounds", min=1, max=MAX_STEPS)  # fmt: skip
    gamma: float = option("discount factor of the dual", min=0.0, max=1.0)
    beta: float = option("share of the expert's transitions in the mixture the f-divergence "
                         "is taken over (the authors implement 0.5 only)", min=0.0,
                         max=1.0)  # fmt: skip
    lam: float = option("weight of the dual's residual terms against the mean utility on the "
                        "offline data (the authors' lamda)", min=0.0, max=1.0,
                        search=Search(0.5, 0.95))  # fmt: skip
    eta: float = option("weight of the backward residual's loss (the authors' ita)", min=0.0)
    temperature: float = option("tau of the policy's weights exp(tau V(s, s'))", min=0.0,
                                search=Search(0.02, 1.0, log=True))
    weight_clip: float = option("the largest weight of a transition in the policy's loss",
                                min=0.0, exclusive=True)  # fmt: skip
    polyak: float = option("step of the utility's target network towards it, per update",
                           min=0.0, max=1.0)  # fmt: skip
    value_lr: float | None = option("Adam's learning rate of V (default: the run's --lr)",
                                    min=0.0, exclusive=True)  # fmt: skip
    policy_lr: float | None = option("Adam's learning rate of the policy (default: the run's "
                                     "--lr)", min=0.0, exclusive=True)  # fmt: skip
    schedule: str = schedule_option("steps", "dilo-steps over the rounds; converged: V and "
                                    "the policy until V's held-out dual stops improving, then "
                                    "the policy alone until its held-out loss does")  # fmt: skip
    check_updates: int = converged_option("check_updates")
    patience_checks: int = converged_option("patience_checks")
    min_fit_updates: int = converged_option("min_fit_updates")
    max_fit_updates: int = converged_option("max_fit_updates")

    @classmethod
    def for_run(cls, config: RunConfig, method: str = "dilo") -> DILOOptions:
        """The options of ``config``'s run: its ``method_options`` over the defaults of its
        env kind, the learning rates the run's where not given.

        Raises:
            ConfigError: An unknown option or a value out of range.
        """
        options = cls.resolve(config.method_options, OPTION_DEFAULTS[env_kind(config.env)],
                              method)  # fmt: skip
        options.value_lr = options.value_lr or config.lr
        options.policy_lr = options.policy_lr or config.lr
        return options


#: The authors' values (``train_dilo.py``): gamma 0.99, beta 0.5, lamda 0.8, ita 0.5,
#: temperature 3/50, weights clipped at 100 (``EXP_ADV_MAX``), Polyak 0.005. Their runs take
#: 300,000 steps with 1,024 offline and 1,024 expert transitions a minibatch; on this project's
#: CPU budget a run takes the run's ``--batch-size`` of each and 5,000 steps on classic
#: control (the utility's loss is flat well before; validation seeds), 2,000 on frames, whose
#: networks are the IDM's and cost a hundred times more a step.
_CLASSIC: dict[str, Any] = {
    "rounds": 3, "steps": 5000, "gamma": 0.99, "beta": 0.5, "lam": 0.8, "eta": 0.5,
    "temperature": 0.06, "weight_clip": 100.0, "polyak": 0.005, "value_lr": None, "policy_lr": None,
    "schedule": "steps", **CONVERGED_DEFAULTS,
}  # fmt: skip
OPTION_DEFAULTS: dict[str, dict[str, Any]] = {
    "classic": _CLASSIC, "maze": {**_CLASSIC, "steps": 2000}, "image": {**_CLASSIC, "steps": 2000},
}
