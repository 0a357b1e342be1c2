"""The BCO family's options (BC, BCO, BCO(alpha), ABCO(alpha), its ablations and IUPE).

Each option is a command-line flag of its own (``abco train --method abco --help``:
``--idm-epochs``, ``--policy-epochs``, ...) and a key of ``--method-options``. ``None`` options
take the defaults of the run's env kind and preset (:data:`DEFAULTS`), then its environment's
(:data:`ENV_DEFAULTS`), then its regime's (:data:`REGIME_DEFAULTS`); the user's values win.

Example:
    >>> from abco_train.config.run import RunConfig
    >>> BCOOptions.for_run(RunConfig(env="AbcoMaze10x10-v0").resolved()).policy_epochs
    10
    >>> BCOOptions.for_run(RunConfig(env="CartPole-v1", method_options={"idm_epochs": 0}))
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: --idm-epochs must be >= 1, got 0
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar

import abco_envs
from abco_train.config.fields import ConfigError, MethodOptions, Search, option
from abco_train.config.limits import MAX_EPOCHS, MAX_PRE_TRANSITIONS, MAX_STEPS
from abco_train.config.run import CELL_ARCHS, IDM_INPUTS, RunConfig, env_kind
from abco_train.methods.converged import CONVERGED_DEFAULTS, converged_option

__all__ = ["BCOOptions", "VARIANTS", "AUGMENTS", "SCHEDULES", "resolved", "DEFAULTS",
           "PRESET_DEFAULTS", "ENV_DEFAULTS", "REGIME_DEFAULTS"]  # fmt: skip

#: Training-time data augmentation: ``none``, or ``transpose`` (mazes: each minibatch
#: example is transposed about the main diagonal with probability 1/2, actions mapped
#: N<->W, S<->E; start and goal stay where they are).
AUGMENTS = ("none", "transpose")
#: How the two networks' fits end: ``epochs`` (their epoch counts, early stopping of the IDM
#: by epochs) or ``converged`` (:mod:`abco_train.methods.bco.converged`).
SCHEDULES = ("epochs", "converged")

_T = TypeVar("_T")


def resolved(value: _T | None) -> _T:
    """A setting that is ``None`` only before resolution (the run config's and the schedule
    options that ``BCOOptions.for_run`` fills in)."""
    assert value is not None, "a setting read before the config and options were resolved"
    return value

#: Method switches: (train the IDM, attention, how I_s is built after iteration 0).
#: ``idm_data``: "pre" = I_pre only (BCO(0)), "pos" = all post-demonstrations (BCO(alpha)),
#: "pre+pos" = I_pre and all post-demonstrations (Torabi et al.'s BCO(alpha)),
#: "partial" / "whole" = ABCO's sampling from winning / all runs; ``None`` = no IDM (BC).
VARIANTS: dict[str, dict[str, Any]] = {
    "bc": {"attention": False, "idm_data": None, "iterative": False},
    "bco": {"attention": False, "idm_data": "pre", "iterative": False},
    "bco-alpha": {"attention": False, "idm_data": "pos", "iterative": True},
    "bco-alpha-torabi": {"attention": False, "idm_data": "pre+pos", "iterative": True},
    "abco": {"attention": True, "idm_data": "partial", "iterative": True},
    "attention": {"attention": True, "idm_data": "pos", "iterative": True},
    "sampling-partial": {"attention": False, "idm_data": "partial", "iterative": True},
    "sampling-whole": {"attention": False, "idm_data": "whole", "iterative": True},
    "abco-whole": {"attention": True, "idm_data": "whole", "iterative": True},
}


#: The epoch counts are read by the epochs schedule only (a converged fit ends on its own).
EPOCHS = (("schedule", "epochs"),)


@dataclass
class BCOOptions(MethodOptions):
    """The IDM's and the policy's schedule of the BCO family; ``None``: the run's default."""

    idm_input: str | None = option("how the IDM reads (s, s'): difference (one encoder over s "
                                   "and s' - s) or pair (each frame encoded apart; images "
                                   "only)", choices=IDM_INPUTS)  # fmt: skip
    idm_epochs: int | None = option("at most this many IDM epochs over I_s per iteration",
                                    min=1, max=MAX_EPOCHS,
                                    search=Search(2, 40, log=True, read_when=EPOCHS))
    idm_patience: int | None = option("stop the IDM's epochs after this many without a better "
                                      "validation accuracy (the best weights are kept)",
                                      min=1, max=MAX_EPOCHS,
                                      search=Search(1, 8, read_when=EPOCHS))
    idm_reinit: bool = option("re-initialise an IDM found at chance after training and train "
                              "it once more (off: Algorithm 1 never re-initialises; the run "
                              "goes on either way)", False)
    idm_validation: int | None = option("pre-demonstration transitions held out to measure "
                                        "the IDM (default: 10%, at most 2,000)",
                                        min=1, max=MAX_PRE_TRANSITIONS)
    idm_samples: int | None = option("cap on N = |I_s| (default: |I_pre|)",
                                     min=1, max=MAX_PRE_TRANSITIONS)
    policy_epochs: int | None = option("policy epochs over the expert data per iteration",
                                       min=1, max=MAX_EPOCHS,
                                       search=Search(1, 16, log=True, read_when=EPOCHS))
    first_epochs_factor: int | None = option("iteration 0 trains both nets this many times "
                                             "longer", min=1, max=MAX_EPOCHS)  # fmt: skip
    min_updates: int | None = option("raise --policy-epochs and --idm-epochs on small data "
                                     "until each makes at least this many minibatch updates "
                                     "(default: 1000 for the general preset, else none)",
                                     min=1, max=MAX_STEPS)
    max_updates: int | None = option("cut each policy unit (--policy-epochs) on large data to "
                                     "at most this many minibatch updates (default: 1000 for "
                                     "the general preset, else none)",
                                     min=1, max=MAX_STEPS)  # fmt: skip
    schedule: str | None = option("how each fit of both networks ends: epochs (their epoch "
                                  "counts) or converged (when its held-out score stops "
                                  "improving: --check-updates, --patience-checks, "
                                  "--min-fit-updates, --max-fit-updates)",
                                  choices=SCHEDULES)  # fmt: skip
    check_updates: int | None = converged_option("check_updates")
    patience_checks: int | None = converged_option("patience_checks")
    min_fit_updates: int | None = converged_option("min_fit_updates")
    max_fit_updates: int | None = converged_option("max_fit_updates")
    augment: str | None = option("training-time augmentation: none, or transpose (mazes: "
                                 "transpose half of each minibatch about the main diagonal, "
                                 "actions N<->W, S<->E) (default: transpose for the general "
                                 "preset, else none)", choices=AUGMENTS)  # fmt: skip

    @classmethod
    def searched(cls, method: str) -> tuple[str, ...]:
        """BC trains no IDM: its search leaves the IDM's options out."""
        names = super().searched(method)
        if VARIANTS.get(method, {}).get("idm_data", "pre") is None:
            return tuple(n for n in names if not n.startswith("idm_"))
        return names

    @classmethod
    def for_run(cls, config: RunConfig, method: str = "abco") -> BCOOptions:
        """The options of ``config``'s run: its ``method_options`` over the defaults.

        Raises:
            ConfigError: An unknown option, a value out of range, or options that do not fit
                the run (e.g. ``idm_input`` ``pair`` for vector states).
        """
        kind = env_kind(config.env)
        defaults = {**DEFAULTS[kind], **PRESET_DEFAULTS.get((kind, config.preset), {}),
                    **ENV_DEFAULTS.get(abco_envs.env_name(config.env), {}),
                    **REGIME_DEFAULTS.get(config.regime, {})}  # fmt: skip
        options = cls.resolve(config.method_options, defaults, method)
        options.check(config)
        return options

    def check(self, config: RunConfig) -> None:
        """The checks between options and the run's other settings.

        Raises:
            ConfigError: The first that fails, naming both settings.
        """
        kind = env_kind(config.env)
        if kind == "classic" and self.idm_input == "pair":
            raise ConfigError("--idm-input pair is for frames; vector IDMs read (s, s' - s)")
        if config.arch in CELL_ARCHS and self.idm_input == "pair":
            raise ConfigError(f"--arch {config.arch} reads a transition as one frame and its "
                              "difference (--idm-input difference): its pooled features of one "
                              "frame do not say where the agent is")  # fmt: skip
        if self.min_updates and self.max_updates and self.min_updates > self.max_updates:
            raise ConfigError(f"--min-updates {self.min_updates} is above --max-updates "
                              f"{self.max_updates}: a policy unit cannot make both")  # fmt: skip
        if (self.min_fit_updates or 0) > (self.max_fit_updates or self.min_fit_updates or 0):
            raise ConfigError(f"--min-fit-updates {self.min_fit_updates} is above "
                              f"--max-fit-updates {self.max_fit_updates}")  # fmt: skip
        if kind != "maze" and self.augment not in (None, "none"):
            raise ConfigError(f"--augment {self.augment} is for maze frames; {config.env} "
                              "takes --augment none")  # fmt: skip


#: Defaults by env kind: mazes train on 64x64 RGB frames, classic control on state vectors.
#: Every kind trains to convergence. Vector tasks: on the headline track's four classic tasks,
#: validation seeds 100-102, the five IfO methods of the family averaged 0.796 with it against
#: 0.307 with the epoch counts, every method higher. Mazes: on ``maze3x3-heldout``'s validation
#: layouts and seeds every method of the family was higher (mean 0.837 -> 0.887, about 2.3x the
#: cell time); on ``maze5x5-heldout`` (the general preset) BC and ABCO(alpha) stayed within
#: seed noise (0.729 -> 0.722, 0.772 -> 0.722) at a fifth and three quarters of the cell time
#: (docs/notes/fair-fight.md). The authors' regime keeps its epochs (:data:`REGIME_DEFAULTS`).
DEFAULTS: dict[str, dict[str, Any]] = {
    "maze": {"idm_input": "difference", "idm_epochs": 4, "idm_patience": 1, "policy_epochs": 3,
             "first_epochs_factor": 3, "idm_samples": 20_000, "schedule": "converged",
             **CONVERGED_DEFAULTS},
    "classic": {"idm_input": "difference", "idm_epochs": 2, "idm_patience": 1,
                "policy_epochs": 4, "first_epochs_factor": 2, "idm_samples": 50_000,
                "schedule": "converged", **CONVERGED_DEFAULTS},
}  # fmt: skip
DEFAULTS["image"] = DEFAULTS["maze"]  # other image envs: the mazes' schedule

#: Changes by (env kind, preset). ``paper``: the paper's ResNet-18 reads each frame apart.
#: ``general`` (unseen layouts): transposed mazes for twice the data, and exactly 1,000 policy
#: updates per epoch setting (at least 1,000 IDM updates), for the 850 expert transitions of
#: 100 layouts as for the 84,000 of 10,000: every K gets the same compute, so a curve over K
#: measures data (docs/training.md).
PRESET_DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {
    ("maze", "paper"): {"idm_input": "pair"},
    ("maze", "general"): {"augment": "transpose", "min_updates": 1_000, "max_updates": 1_000},
}

#: Per-environment changes (any preset).
ENV_DEFAULTS: dict[str, dict[str, Any]] = {
    # 2x2-pixel cells on 64x64 frames: both networks need longer to resolve them.
    "AbcoMaze10x10-v0": {"idm_epochs": 2, "policy_epochs": 10},
}

#: The authors' schedule (their public code, where the paper is silent): one IDM epoch and one
#: policy epoch per iteration, no longer first iteration (more iterations:
#: :data:`abco_train.config.defaults.REGIME_DEFAULTS`).
REGIME_DEFAULTS: dict[str, dict[str, Any]] = {
    "authors": {"idm_epochs": 1, "policy_epochs": 1, "first_epochs_factor": 1,
                "schedule": "epochs"},
}
