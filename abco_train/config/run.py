"""The run config: every setting of a training run, its defaults, its checks, its options.

One :class:`RunConfig` describes a run. Fields left ``None`` take the default of the run's
environment kind and preset from :data:`DEFAULTS` (a table you can read), then
:data:`ENV_DEFAULTS` for single environments, then :data:`REGIME_DEFAULTS`, then with
``layouts`` the procedural datasets (:data:`LAYOUT_DEFAULTS`), then the method's own defaults
(:meth:`abco_train.methods.base.Method.defaults`). ``eval_fresh`` stays ``None`` (on with
``layouts``: :func:`fresh_evaluation`), so the configs of runs made before it still match.
:data:`RUNTIME_FIELDS` may change between a run and its resumption; every other field is part
of the run's identity.

The command lines of ``abco train`` and ``abco bench`` are both generated from the fields by
:func:`add_config_options` (help text from each field's ``help`` metadata, choices and lower
bounds from its ``choices``/``min`` metadata), so the two cannot drift apart.

Importing this module imports neither torch nor gymnasium.

Example:
    >>> cfg = RunConfig(env="CartPole-v1").resolved()
    >>> cfg.arch, cfg.batch_size, cfg.eval_episodes
    ('mlp', 512, 100)
    >>> RunConfig(env="AbcoMaze10x10-v0").resolved().policy_epochs
    10
    >>> RunConfig(batch_size=0).validate()
    Traceback (most recent call last):
    ...
    abco_train.config.run.ConfigError: --batch-size must be >= 1, got 0
"""

from __future__ import annotations

import argparse
import json
import types
import typing
from collections.abc import Collection, Mapping
from dataclasses import MISSING, asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import abco_envs

__all__ = [
    "RunConfig", "ConfigError", "DEFAULTS", "ENV_DEFAULTS", "RUNTIME_FIELDS", "PRESETS",
    "PROTOCOLS", "ARCHS", "CELL_ARCHS", "ARCHS_BY_KIND", "DEVICES", "IDM_INPUTS", "REGIMES",
    "AUGMENTS", "REGIME_DEFAULTS", "LAYOUT_DEFAULTS", "PROCEDURAL_ENVS",
    "MAX_LAYOUTS", "env_kind", "known_envs",
    "comparable", "procedural_dataset", "fresh_evaluation",
    "add_config_options", "config_from_args", "flag_of",
]  # fmt: skip

PRESETS = ("cpu", "paper", "general")
PROTOCOLS = ("paper", "standard")
#: Encoder architectures: ``mlp`` (vector states), ``cnn`` (compact, CPU default for images),
#: ``resnet18`` (the paper's image network), ``cellnet`` (mazes: per-cell features, a
#: recurrent convolution over the cell grid and a global read-out), ``cellplan`` (the same
#: with a value-iteration planner in the policy; the ``general`` preset's).
ARCHS = ("mlp", "cnn", "resnet18", "cellnet", "cellplan")
#: The maze networks that read the frame cell by cell (:mod:`abco_train.networks.cells`).
CELL_ARCHS = ("cellnet", "cellplan")
DEVICES = ("auto", "cpu", "cuda")
#: How the IDM reads a transition (:class:`abco_train.networks.builders.IDMNet`).
IDM_INPUTS = ("difference", "pair")
#: ``default``: abco's data and schedule; ``authors``: the authors' (see REGIME_DEFAULTS).
REGIMES = ("default", "authors")
ARCHS_BY_KIND = {"maze": ("cnn", "resnet18", *CELL_ARCHS), "classic": ("mlp",)}
#: Training-time data augmentation: ``none``, or ``transpose`` (mazes: each minibatch
#: example is transposed about the main diagonal with probability 1/2, actions mapped
#: N<->W, S<->E; start and goal stay where they are).
AUGMENTS = ("none", "transpose")
#: The mazes with procedural datasets (``abco_data.registry.PROCEDURAL_ENVS``), which
#: ``--layouts`` trains on, and their number of layouts.
PROCEDURAL_ENVS = ("AbcoMaze5x5-v0", "AbcoMaze10x10-v0")
MAX_LAYOUTS = 10_000


class ConfigError(ValueError):
    """A setting out of its range or choices; the message names the option and the value."""


def env_kind(env_id: str) -> str:
    """``"maze"`` for the abco mazes, ``"classic"`` for classic control (the defaults' key).

    Raises:
        ConfigError: ``env_id`` is none of the six environments abco trains on.
    """
    name = abco_envs.env_name(env_id)
    if abco_envs.is_maze(name):
        return "maze"
    if name in abco_envs.CLASSIC_IDS:
        return "classic"
    raise ConfigError(f"unknown env id {env_id!r}; abco trains on: {', '.join(known_envs())}")


def start_cell_dataset(env_id: str) -> str:
    """The maze's pre-demonstrations from the start cell without wall hits (authors regime)."""
    n = abco_envs.maze_size(env_id)
    return f"abco/maze{n}x{n}-pre-start-v0"


def procedural_dataset(kind: str) -> Any:
    """A callable default: the env's procedural ``kind`` (``expert`` or ``pre``) dataset id."""

    def dataset(env_id: str) -> str:
        n = abco_envs.maze_size(env_id)
        return f"abco/maze{n}x{n}-procedural-{kind}-v0"

    return dataset


def fresh_evaluation(config: RunConfig) -> bool:
    """Whether the final evaluation also covers fresh layouts: ``--eval-fresh`` if given,
    else for runs that train on procedural layouts (``--layouts``), mazes only."""
    if env_kind(config.env) != "maze":
        return False
    return bool(config.eval_fresh) if config.eval_fresh is not None else config.layouts is not None


def known_envs() -> tuple[str, ...]:
    """The environments abco trains on."""
    return (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)


def _opt(help: str, default: Any = None, **meta: Any) -> Any:
    """A config field with its help text (and ``choices``/``min`` checks) as metadata."""
    return field(default=default, metadata={"help": help, **meta})


@dataclass
class RunConfig:
    """Every setting of a run; ``None`` means "the default for this env, preset and method".

    The help of each field (``abco train --help``) is its ``help`` metadata.
    """

    env: str = _opt("environment id: AbcoMaze3x3/5x5/10x10-v0, CartPole-v1, Acrobot-v1, "
                    "MountainCar-v0", "AbcoMaze5x5-v0")  # fmt: skip
    method: str = _opt("a registered method: bc, bco, bco-alpha, abco, attention, "
                       "sampling-partial, sampling-whole, abco-whole, or a plugin's", "abco")
    seed: int = _opt("seed of everything (same seed, same CPU run)", 0, min=0)
    preset: str = _opt("cpu (compact CNN on images), paper (the paper's ResNet-18) or general "
                       "(mazes: a network that reasons over the whole maze, for unseen layouts)",
                       "cpu", choices=PRESETS)  # fmt: skip
    regime: str = _opt("default (abco's data and schedule) or authors (the authors': start-cell "
                       "pre-demonstrations without wall hits, one IDM and one policy epoch per "
                       "iteration, alpha 10)", "default", choices=REGIMES)
    iterations: int | None = _opt("alpha: iterations 0..alpha run (iterative methods)", min=0)
    arch: str | None = _opt("network: mlp (vectors), cnn, resnet18, cellnet or cellplan (images)",
                            choices=ARCHS)  # fmt: skip
    attention: bool | None = _opt("self-attention in both networks (default: the method's)")
    idm_input: str | None = _opt("how the IDM reads (s, s'): difference (one encoder over s and "
                                 "s' - s) or pair (each frame encoded apart; images only)",
                                 choices=IDM_INPUTS)  # fmt: skip
    idm_epochs: int | None = _opt("at most this many IDM epochs over I_s per iteration", min=1)
    idm_patience: int | None = _opt("stop the IDM's epochs after this many without a better "
                                    "validation accuracy (the best weights are kept)", min=1)
    idm_validation: int | None = _opt("pre-demonstration transitions held out to measure the "
                                      "IDM (default: 10%, at most 2,000)", min=1)
    policy_epochs: int | None = _opt("policy epochs over the expert data per iteration", min=1)
    min_updates: int | None = _opt("raise --policy-epochs and --idm-epochs on small data until "
                                   "each makes at least this many minibatch updates (default: "
                                   "1000 for the general preset, else none)", min=1)
    max_updates: int | None = _opt("cut each policy unit (--policy-epochs) on large data to at "
                                   "most this many minibatch updates (default: 1000 for the "
                                   "general preset, else none)", min=1)
    first_epochs_factor: int | None = _opt("iteration 0 trains both nets this many times longer",
                                           min=1)  # fmt: skip
    batch_size: int | None = _opt("minibatch size", min=1)
    lr: float | None = _opt("Adam learning rate of both networks", min=0.0, exclusive=True)
    idm_samples: int | None = _opt("cap on N = |I_s| (default |I_pre|)", min=1)
    pre_transitions: int | None = _opt("use at most this many pre-demonstration transitions",
                                       min=1)  # fmt: skip
    expert_episodes: int | None = _opt("use at most this many expert episodes", min=1)
    layouts: int | None = _opt("mazes 5x5 and 10x10: train on the first K layouts of the "
                               "procedural datasets (abco/maze{n}-procedural-{expert,pre}-v0 "
                               "unless --expert-data/--pre-data name others) (default: the "
                               "standard datasets, all their layouts)", min=1)
    augment: str | None = _opt("training-time augmentation: none, or transpose (mazes: "
                               "transpose half of each minibatch about the main diagonal, "
                               "actions N<->W, S<->E) (default: transpose for the general "
                               "preset, else none)", choices=AUGMENTS)
    eval_episodes: int | None = _opt("classic control: episodes per evaluation", min=1)
    eval_layouts: int | None = _opt("mazes: evaluate the first k layouts only (tests)", min=1)
    eval_fresh: bool | None = _opt("mazes: also evaluate the final policy on 100 fresh layouts, "
                                   "in no dataset (default: on with --layouts, else off)")
    protocol: str = _opt("maze evaluation protocol while training: paper (4th visit of a cell "
                         "ends, return -1) or standard", "paper", choices=PROTOCOLS)
    eval_max_steps: int | None = _opt("cap on evaluation episode length (default: the env's)",
                                      min=1)  # fmt: skip
    expert_data: str | None = _opt("expert dataset id or HDF5 file (default: the env's)")
    pre_data: str | None = _opt("pre-demonstration dataset id or HDF5 file (default: the env's)")
    cache_dir: str | None = _opt("abco dataset cache (default $ABCO_DATA_HOME)")
    run_dir: str | None = _opt("run folder (default runs/{env}-{method}-s{seed})")
    device: str = _opt("where the networks train and act: auto (cuda if available), cpu or "
                       "cuda", "auto", choices=DEVICES)
    threads: int = _opt("torch threads; 1 stays fast when other processes share the cores "
                        "(more threads spin-wait on each other under load)", 1, min=1)
    deterministic: bool = _opt("deterministic torch kernels", True)
    quiet: bool = _opt("no progress bars", False)
    plot_layouts: int = _opt("mazes: layouts whose paths are drawn", 4, min=0)
    plots: bool = _opt("draw the figures at the end", True)
    method_options: dict[str, Any] = field(
        default_factory=dict, metadata={"help": "JSON object of method-specific options"}
    )

    def resolved(self, method_defaults: Mapping[str, Any] | None = None) -> RunConfig:
        """A copy with every ``None`` field filled in.

        Order: :data:`DEFAULTS` of the env kind and preset, then :data:`ENV_DEFAULTS`, then
        :data:`REGIME_DEFAULTS`, then with ``layouts`` :data:`LAYOUT_DEFAULTS`, then
        ``method_defaults`` (the method's own, :meth:`abco_train.methods.base.Method.defaults`);
        fields set by the user always win.
        """
        key = (env_kind(self.env), self.preset)
        if key not in DEFAULTS:
            if self.preset in PRESETS:
                fits = sorted(p for k, p in DEFAULTS if k == key[0])
                raise ConfigError(f"--preset {self.preset} is not for {self.env}; use "
                                  f"{' or '.join(fits)}")  # fmt: skip
            raise ConfigError(f"--preset must be one of {', '.join(PRESETS)}, got {self.preset!r}")
        name = abco_envs.env_name(self.env)
        base = {**DEFAULTS[key], **ENV_DEFAULTS.get(name, {}),
                **REGIME_DEFAULTS.get((key[0], self.regime), {}),
                **(LAYOUT_DEFAULTS if self.layouts is not None else {}),
                **(method_defaults or {})}  # fmt: skip
        values = asdict(self)
        for name, default in base.items():
            if values[name] is None:  # a callable default depends on the env (a dataset id)
                values[name] = default(self.env) if callable(default) else default
        if values["run_dir"] is None:
            layouts = "" if self.layouts is None else f"-K{self.layouts}"
            name = f"{self.env}-{self.method}{layouts}-s{self.seed}"
            values["run_dir"] = str(Path("runs") / name)
        return RunConfig(**values)

    def validate(self) -> RunConfig:
        """Check every set field against its choices and lower bound; return ``self``.

        Raises:
            ConfigError: The first field out of range, named as its command-line option.
        """
        kind = env_kind(self.env)
        if kind == "classic" and self.idm_input == "pair":
            raise ConfigError("--idm-input pair is for frames; vector IDMs read (s, s' - s)")
        if self.arch is not None and self.arch in ARCHS and self.arch not in ARCHS_BY_KIND[kind]:
            raise ConfigError(f"--arch {self.arch} does not fit {self.env}'s observations; use "
                              f"{' or '.join(ARCHS_BY_KIND[kind])}")  # fmt: skip
        if self.arch in CELL_ARCHS and self.idm_input == "pair":
            raise ConfigError(f"--arch {self.arch} reads a transition as one frame and its "
                              "difference (--idm-input difference): its pooled features of one "
                              "frame do not say where the agent is")  # fmt: skip
        if self.min_updates and self.max_updates and self.min_updates > self.max_updates:
            raise ConfigError(f"--min-updates {self.min_updates} is above --max-updates "
                              f"{self.max_updates}: a policy unit cannot make both")  # fmt: skip
        if kind == "classic" and self.augment not in (None, "none"):
            raise ConfigError(f"--augment {self.augment} is for maze frames; classic control "
                              "takes --augment none")  # fmt: skip
        if kind == "classic" and self.eval_fresh:
            raise ConfigError("--eval-fresh is for mazes: classic control has no layouts")
        if self.layouts is not None and abco_envs.env_name(self.env) not in PROCEDURAL_ENVS:
            raise ConfigError(f"--layouts needs a maze with procedural datasets "
                              f"({' or '.join(PROCEDURAL_ENVS)}), got --env {self.env}"
                              + (" (a 3x3 grid has too few layouts)" if kind == "maze"
                                 else ""))  # fmt: skip
        if isinstance(self.layouts, int) and self.layouts > MAX_LAYOUTS:
            raise ConfigError(f"--layouts must be <= {MAX_LAYOUTS:,} (the layouts of the "
                              f"procedural datasets), got {self.layouts}")  # fmt: skip
        if self.layouts is not None and self.regime == "authors" and self.pre_data is None:
            raise ConfigError("--regime authors brings its own pre-demonstrations (the pool's "
                              "start-cell walks, 100 layouts); with --layouts give --pre-data "
                              "too, or use --regime default")  # fmt: skip
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            choices, low = f.metadata.get("choices"), f.metadata.get("min")
            if choices is not None and value not in choices:
                raise ConfigError(f"{flag_of(f.name)} must be one of {', '.join(choices)}, "
                                  f"got {value!r}")  # fmt: skip
            if low is not None:
                exclusive = f.metadata.get("exclusive", False)
                if value < low or (exclusive and value == low):
                    sign = ">" if exclusive else ">="
                    raise ConfigError(f"{flag_of(f.name)} must be {sign} {low}, got {value}")
        if not isinstance(self.method_options, dict):
            raise ConfigError(f"--method-options must be a JSON object, got "
                              f"{self.method_options!r}")  # fmt: skip
        return self

    def to_json(self) -> str:
        """The config as JSON (``config.json`` of a run folder)."""
        return json.dumps(asdict(self), indent=2, sort_keys=True)

    def replace(self, **changes: Any) -> RunConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


#: Defaults of the ``None`` fields by (env kind, preset). Mazes train on 64x64 RGB frames,
#: classic control on state vectors; ``paper`` is the paper's ResNet-18 and its optimiser.
DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {
    ("maze", "cpu"): {
        "iterations": 2, "arch": "cnn", "attention": True, "idm_input": "difference",
        "idm_epochs": 4, "idm_patience": 1, "policy_epochs": 3, "first_epochs_factor": 3,
        "batch_size": 64, "lr": 1e-3, "idm_samples": 20_000,
    },
    ("maze", "paper"): {
        "iterations": 2, "arch": "resnet18", "attention": True, "idm_input": "pair",
        "idm_epochs": 4, "idm_patience": 1, "policy_epochs": 3, "first_epochs_factor": 3,
        "batch_size": 32, "lr": 1e-4, "idm_samples": 20_000,
    },
    # Unseen layouts: per-cell features, a recurrent convolution and value iteration over the
    # cell grid (no weight tied to a position), transposed mazes for twice the data, and
    # exactly 1,000 policy updates per epoch setting (at least 1,000 IDM updates), for the 850
    # expert transitions of 100 layouts as for the 84,000 of 10,000: every K gets the same
    # compute, so a curve over K measures data (docs/training.md).
    ("maze", "general"): {
        "iterations": 2, "attention": True, "idm_input": "difference",
        "idm_epochs": 4, "idm_patience": 1, "policy_epochs": 3, "first_epochs_factor": 3,
        "batch_size": 64, "lr": 1e-3, "idm_samples": 20_000, "augment": "transpose",
        "min_updates": 1_000, "max_updates": 1_000, "arch": "cellplan",
    },
    ("classic", "cpu"): {
        "iterations": 2, "arch": "mlp", "attention": True, "idm_input": "difference",
        "idm_epochs": 2, "idm_patience": 1, "policy_epochs": 4, "first_epochs_factor": 2,
        "batch_size": 512, "lr": 3e-3, "idm_samples": 50_000, "eval_episodes": 100,
    },
    ("classic", "paper"): {
        "iterations": 2, "arch": "mlp", "attention": True, "idm_input": "difference",
        "idm_epochs": 2, "idm_patience": 1, "policy_epochs": 4, "first_epochs_factor": 2,
        "batch_size": 32, "lr": 1e-3, "idm_samples": 50_000, "eval_episodes": 100,
    },
}  # fmt: skip

#: Per-environment changes on top of :data:`DEFAULTS` (any preset).
ENV_DEFAULTS: dict[str, dict[str, Any]] = {
    # 2x2-pixel cells on 64x64 frames: both networks need longer to resolve them.
    "AbcoMaze10x10-v0": {"idm_epochs": 2, "policy_epochs": 10},
    # Every Acrobot rollout reaches the goal, so after iteration 0 the IDM learns from I_pos
    # alone and its accuracy on the expert's (fast, off-I_pre) states rises each iteration
    # (0.84 -> 0.97 -> 0.99); the policy follows, and its training-time AER stops improving
    # only at about iteration 15-30 (alpha 10: -79.95, alpha 30: -77.67 on the validation
    # seeds; every seed better). Iterations cost seconds. Chosen on validation seeds 100-102
    # (docs/results/progress-issue9.md), not on reported seeds.
    "Acrobot-v1": {"iterations": 30},
}

#: The datasets of a run with ``--layouts`` (unless ``--expert-data`` / ``--pre-data`` are
#: given): the procedural datasets of its maze, whose first K layouts it trains on.
LAYOUT_DEFAULTS: dict[str, Any] = {"expert_data": procedural_dataset("expert"),
                                   "pre_data": procedural_dataset("pre")}

#: The authors' data and schedule (their public code, where the paper is silent), on top of
#: the table above: one IDM epoch and one policy epoch per iteration, no longer first
#: iteration, more iterations; for mazes, pre-demonstrations recorded as an agent that resets
#: the env would: from the start cell, moves into walls dropped (``{maze}-pre-start-v0``).
#: A callable default is called with the env id.
REGIME_DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {
    ("maze", "authors"): {"idm_epochs": 1, "policy_epochs": 1, "first_epochs_factor": 1,
                          "iterations": 10, "pre_data": start_cell_dataset},
    ("classic", "authors"): {"idm_epochs": 1, "policy_epochs": 1, "first_epochs_factor": 1,
                             "iterations": 10},
}  # fmt: skip

#: Settings that may differ between a run and its resumption (and between a finished grid
#: cell and a re-run of the grid): where things are, how loud, how many threads.
# The datasets (expert_data, pre_data) are part of a run's identity: a finished run asked for
# with other data is another run, not a result to hand back.
RUNTIME_FIELDS = ("quiet", "run_dir", "cache_dir", "threads", "device", "plots", "plot_layouts")


def comparable(config: Mapping[str, Any]) -> dict[str, Any]:
    """The fields of a config (as a dict) that make a run what it is (no runtime fields)."""
    return {k: v for k, v in config.items() if k not in RUNTIME_FIELDS}


# -- command line ---------------------------------------------------------------------------


def flag_of(name: str) -> str:
    """The command-line option of a field: ``idm_epochs`` -> ``--idm-epochs``."""
    return "--" + name.replace("_", "-")


def _base_type(hint: Any) -> Any:
    """``int`` of ``int | None``; the type itself otherwise."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return args[0]
    return typing.get_origin(hint) or hint


def _json_object(text: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("expected a JSON object, e.g. '{\"k\": 1}'")
    return value


def add_config_options(
    parser: argparse.ArgumentParser | Any,
    *,
    exclude: Collection[str] = (),
    unset_defaults: bool = False,
) -> None:
    """Add one option per :class:`RunConfig` field to ``parser`` (or an argument group).

    Args:
        parser: The parser or argument group.
        exclude: Fields left out.
        unset_defaults: Every option defaults to ``None`` ("not set"), as for ``abco bench``'s
            overrides; otherwise an option defaults to its field's default.
    """
    hints = typing.get_type_hints(RunConfig)
    for f in fields(RunConfig):
        if f.name in exclude:
            continue
        kind = _base_type(hints[f.name])
        default = None if f.default is MISSING else f.default
        shown = "per env, preset and method (abco_train.config.run.DEFAULTS)" if default is None \
            else default  # fmt: skip
        help_text = f.metadata.get("help", "")
        option_default = None if unset_defaults else default
        if "(default:" not in help_text:  # a help text may name its default itself
            help_text += f" (default: {shown})"
        kwargs: dict[str, Any] = {"default": option_default, "dest": f.name,
                                  "help": help_text.replace("%", "%%")}  # fmt: skip
        if kind is bool:
            parser.add_argument(flag_of(f.name), action=argparse.BooleanOptionalAction, **kwargs)
        elif kind is dict:
            kwargs["default"] = None if unset_defaults else {}
            parser.add_argument(flag_of(f.name), type=_json_object, metavar="JSON", **kwargs)
        else:
            choices = f.metadata.get("choices")
            parser.add_argument(flag_of(f.name), type=kind, choices=choices, **kwargs)


def config_from_args(args: argparse.Namespace, **fixed: Any) -> RunConfig:
    """The :class:`RunConfig` of parsed options (``None`` options keep the field default)."""
    values: dict[str, Any] = {}
    for f in fields(RunConfig):
        value = fixed.get(f.name, getattr(args, f.name, None))
        if value is not None:
            values[f.name] = value
    return RunConfig(**values)
