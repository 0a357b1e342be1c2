"""The run config: the harness's settings of a training run, their defaults and checks.

One :class:`RunConfig` describes a run. Fields left ``None`` take the defaults of
:mod:`abco_train.config.defaults` (by env kind and preset, environment, regime, ``--layouts``,
then the method's own). A method's own settings are its typed options
(:class:`abco_train.config.fields.MethodOptions`), stored resolved in ``method_options``.
``eval_fresh`` stays ``None`` (on with ``layouts``: :func:`fresh_evaluation`), so the configs
of runs made before it still match. :data:`RUNTIME_FIELDS` may change between a run and its
resumption; every other field is part of the run's identity.

The command lines of ``abco train`` and ``abco bench`` are both generated from the fields by
:func:`add_config_options` (:func:`abco_train.config.fields.add_field_options`), so the two
cannot drift apart.

Importing this module imports neither torch nor gymnasium.

Example:
    >>> cfg = RunConfig(env="CartPole-v1").resolved()
    >>> cfg.arch, cfg.batch_size, cfg.eval_episodes
    ('mlp', 512, 100)
    >>> RunConfig(env="Acrobot-v1").resolved().iterations
    30
    >>> RunConfig(batch_size=0).validate()
    Traceback (most recent call last):
    ...
    abco_train.config.fields.ConfigError: --batch-size must be >= 1, got 0
"""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Collection, Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import abco_envs
from abco_data.registry import PROCEDURAL_ENVS
from abco_envs.maze.procedural import PROCEDURAL_SPLIT_SIZE
from abco_train.config.defaults import (
    DEFAULTS,
    ENV_DEFAULTS,
    LAYOUT_DEFAULTS,
    REGIME_DEFAULTS,
)
from abco_train.config.envs import BUILTIN_ENVS, env_spaces, is_builtin_env, parse_success
from abco_train.config.fields import ConfigError, Search, add_field_options, check_fields, option
from abco_train.config.limits import (
    MAX_BATCH_SIZE,
    MAX_BUDGET,
    MAX_EVAL_EPISODES,
    MAX_EVAL_MAX_STEPS,
    MAX_EXPERT_EPISODES,
    MAX_ITERATIONS,
    MAX_PLOT_LAYOUTS,
    MAX_PRE_TRANSITIONS,
    MAX_SEED,
    MAX_THREADS,
)

__all__ = [
    "RunConfig", "ConfigError", "default_run_name", "RUNTIME_FIELDS", "PRESETS",
    "PROTOCOLS", "ARCHS", "CELL_ARCHS", "ARCHS_BY_KIND", "DEVICES", "IDM_INPUTS", "REGIMES",
    "MAX_LAYOUTS",
    "MOVED_TO_METHOD_OPTIONS", "MAX_SEED", "MAX_THREADS", "MAX_ITERATIONS", "MAX_BATCH_SIZE",
    "MAX_PRE_TRANSITIONS", "MAX_EXPERT_EPISODES", "MAX_EVAL_EPISODES", "MAX_EVAL_MAX_STEPS",
    "MAX_PLOT_LAYOUTS", "env_kind", "known_envs", "comparable", "fresh_evaluation",
    "evaluation_blocks", "HELD_OUT", "validation_block",
    "add_config_options", "config_from_args",
]  # fmt: skip

PRESETS = ("cpu", "paper", "general")
PROTOCOLS = ("paper", "standard")
#: The unseen layouts a maze run's final evaluation plays: ``test`` (the test split, and fresh
#: layouts with :func:`fresh_evaluation`) or ``validation`` (layouts disjoint from those, for
#: runs that choose settings; their block is ``validation/{protocol}``).
HELD_OUT = ("test", "validation")
#: Encoder architectures: ``mlp`` (vector states), ``cnn`` (compact, CPU default for images),
#: ``resnet18`` (the paper's image network), ``cellnet`` (mazes: per-cell features, a
#: recurrent convolution over the cell grid and a global read-out), ``cellplan`` (the same
#: with a value-iteration planner in the policy; the ``general`` preset's).
ARCHS = ("mlp", "cnn", "resnet18", "cellnet", "cellplan")
#: The maze networks that read the frame cell by cell (:mod:`abco_train.networks.cells`).
CELL_ARCHS = ("cellnet", "cellplan")
DEVICES = ("auto", "cpu", "cuda")
#: How an IDM reads a transition (:class:`abco_train.networks.heads.IDMNet`).
IDM_INPUTS = ("difference", "pair")
#: ``default``: abco's data and schedule; ``authors``: the authors' (see REGIME_DEFAULTS).
REGIMES = ("default", "authors")
#: The networks each env kind takes (:func:`env_kind`).
ARCHS_BY_KIND = {"maze": ("cnn", "resnet18", *CELL_ARCHS), "classic": ("mlp",),
                 "image": ("cnn", "resnet18")}
#: ``--layouts`` trains on the first K of the procedural datasets' layouts (``--eval-layouts``:
#: no split holds more).
MAX_LAYOUTS = PROCEDURAL_SPLIT_SIZE

#: Settings that were fields of the run config before they became the BCO family's options
#: (:class:`abco_train.methods.bco.options.BCOOptions`); a ``config.json`` that has them at
#: its top level is read with them moved into ``method_options``
#: (:func:`abco_train.methods.registry.config_from_record`).
MOVED_TO_METHOD_OPTIONS = ("idm_input", "idm_epochs", "idm_patience", "idm_validation",
                           "policy_epochs", "min_updates", "max_updates",
                           "first_epochs_factor", "idm_samples", "augment")  # fmt: skip


def env_kind(env_id: str) -> str:
    """The defaults' key of an env: ``"maze"`` for the abco mazes, ``"classic"`` for vector
    observations (classic control, LunarLander, and any other env with a ``Box`` vector),
    ``"image"`` for any other env with ``uint8`` image observations (read from its spaces:
    :func:`abco_train.config.envs.env_spaces`).

    Raises:
        ConfigError: ``env_id`` is not a string, no registered Gymnasium id, or an env whose
            spaces abco does not learn from (the message says what it takes).
    """
    if not isinstance(env_id, str):
        raise ConfigError(f"--env must be an env id, got {env_id!r}")
    name = abco_envs.env_name(env_id)
    if abco_envs.is_maze(name):
        return "maze"
    if name in abco_envs.CLASSIC_IDS:
        return "classic"
    return env_spaces(env_id).kind


def fresh_evaluation(config: RunConfig) -> bool:
    """Whether the final evaluation also covers fresh layouts: ``--eval-fresh`` if given,
    else for runs that train on procedural layouts (``--layouts``), mazes only."""
    if env_kind(config.env) != "maze":
        return False
    return bool(config.eval_fresh) if config.eval_fresh is not None else config.layouts is not None


def evaluation_blocks(config: RunConfig) -> tuple[str, ...]:
    """The blocks of ``config``'s final evaluation (``final.json`` keys): mazes
    ``{train,test[,fresh]}/{paper,standard}`` (a validation run: ``{train,validation}/...``),
    other envs ``episodes``."""
    if env_kind(config.env) != "maze":
        return ("episodes",)
    if config.held_out == "validation":
        splits: tuple[str, ...] = ("train", "validation")
    else:
        splits = ("train", "test", "fresh") if fresh_evaluation(config) else ("train", "test")
    return tuple(f"{s}/{p}" for s in splits for p in PROTOCOLS)


def validation_block(block: str) -> str:
    """The block of a validation run (``held_out="validation"``) that stands for ``block`` of a
    test run: the held-out layouts' (``test`` or ``fresh``) become ``validation``'s, the others
    stay.

    Example:
        >>> validation_block("test/paper"), validation_block("fresh/standard")
        ('validation/paper', 'validation/standard')
        >>> validation_block("train/paper"), validation_block("episodes")
        ('train/paper', 'episodes')
    """
    split, _, protocol = block.partition("/")
    return f"validation/{protocol}" if split in ("test", "fresh") and protocol else block


def known_envs() -> tuple[str, ...]:
    """The environments abco ships datasets for (it trains on any registered Gymnasium env
    with ``Box`` observations and ``Discrete`` actions, given datasets: :func:`env_kind`)."""
    return BUILTIN_ENVS


@dataclass
class RunConfig:
    """Every setting of a run; ``None`` means "the default for this env, preset and method".

    The help of each field (``abco train --help``) is its ``help`` metadata.
    """

    env: str = option("environment id: AbcoMaze3x3/5x5/10x10-v0, CartPole-v1, Acrobot-v1, "
                      "MountainCar-v0, LunarLander-v3 (extra box2d), or any registered "
                      "Gymnasium id with Box observations and Discrete actions (module:Id-v0 "
                      "imports module first; give --expert-data and --pre-data)",
                      "AbcoMaze5x5-v0")  # fmt: skip
    method: str = option("a registered method (abco train --help lists them) or a plugin's",
                         "abco")
    seed: int = option("seed of everything (same seed, same CPU run)", 0, min=0,
                     max=MAX_SEED)
    preset: str = option("cpu (compact CNN on images), paper (the paper's ResNet-18: hours on "
                         "a 2-core CPU, minutes on a GPU) or general (mazes: a network that "
                         "reasons over the whole maze, for unseen layouts)", "cpu",
                         choices=PRESETS)  # fmt: skip
    regime: str = option("default (abco's data and schedule) or authors (the authors': start-cell "
                         "pre-demonstrations without wall hits, one IDM and one policy epoch per "
                         "iteration, alpha 10)", "default", choices=REGIMES)
    iterations: int | None = option("alpha: iterations 0..alpha run (iterative methods)", min=0,
                                    max=MAX_ITERATIONS)
    arch: str | None = option("network: mlp (vectors), cnn, resnet18, cellnet or cellplan (images)",
                              choices=ARCHS)  # fmt: skip
    attention: bool | None = option("self-attention in both networks (default: the method's)")
    batch_size: int | None = option("minibatch size", min=1, max=MAX_BATCH_SIZE)
    lr: float | None = option("Adam learning rate of both networks", min=0.0, exclusive=True,
                              search=Search(1e-4, 1e-2, log=True))  # every method's, tuned
    pre_transitions: int | None = option("use at most this many pre-demonstration transitions",
                                         min=1, max=MAX_PRE_TRANSITIONS)  # fmt: skip
    expert_episodes: int | None = option("use at most this many expert episodes", min=1,
                                         max=MAX_EXPERT_EPISODES)  # fmt: skip
    layouts: int | None = option("mazes 5x5 and 10x10: train on the first K layouts of the "
                                 "procedural datasets (abco/maze{n}-procedural-{expert,pre}-v0 "
                                 "unless --expert-data/--pre-data name others) (default: the "
                                 "standard datasets, all their layouts)", min=1)
    eval_episodes: int | None = option("classic control: episodes per evaluation", min=1,
                                       max=MAX_EVAL_EPISODES)  # fmt: skip
    eval_layouts: int | None = option("mazes: evaluate the first k layouts only (tests)", min=1,
                                      max=MAX_LAYOUTS)  # fmt: skip
    eval_fresh: bool | None = option("mazes: also evaluate the final policy on 100 fresh layouts, "
                                     "in no dataset (default: on with --layouts, else off)")
    held_out: str = option("mazes: the unseen layouts of the final evaluation: test (the test "
                           "split, and fresh layouts with --eval-fresh) or validation (layouts "
                           "disjoint from both, in no expert episode of the run: for choosing "
                           "settings; abco bench sets it on a track's validation seeds)", "test",
                           choices=HELD_OUT)  # fmt: skip
    protocol: str = option("maze evaluation protocol while training: paper (4th visit of a cell "
                           "ends, return -1) or standard", "paper", choices=PROTOCOLS)
    success: str | None = option("when an evaluation episode counts as a success, where the "
                                 "env's info reports no is_success: terminated, return>=X or "
                                 "steps>=N (default: the built-in env's rule; other envs: "
                                 "terminated)")
    eval_max_steps: int | None = option("cap on evaluation episode length (default: the env's)",
                                        min=1, max=MAX_EVAL_MAX_STEPS)  # fmt: skip
    expert_data: str | None = option("expert dataset id or HDF5 file (default: the env's)")
    pre_data: str | None = option("pre-demonstration dataset id or HDF5 file (default: the env's)")
    cache_dir: str | None = option("abco dataset cache (default $ABCO_DATA_HOME)")
    run_dir: str | None = option("run folder (default runs/{env}-{method}-s{seed}, with the "
                                 "preset and regime where they are not the defaults)")
    device: str = option("where the networks train and act: auto (cuda if available, but the "
                         "cpu for vector observations, where a GPU does not pay), cpu or cuda",
                         "auto", choices=DEVICES)
    threads: int = option("torch threads; 1 stays fast when other processes share the cores "
                          "(more threads spin-wait on each other under load)", 1, min=1,
                         max=MAX_THREADS)
    deterministic: bool = option("deterministic torch kernels", True)
    quiet: bool = option("no progress bars", False)
    plot_layouts: int = option("mazes: layouts whose paths are drawn", 4, min=0,
                               max=MAX_PLOT_LAYOUTS)
    plots: bool = option("draw the figures at the end", True)
    task: str | None = option("the benchmark task this run is a cell of (set by abco bench from "
                              "a task file; recorded in final.json)")
    budget: int | None = option("environment interactions the run may spend, all kinds summed "
                                "(pre- and post-demonstrations, RL, remapping); training stops "
                                "when it is spent (default: no cap)", min=1,
                                max=MAX_BUDGET)  # fmt: skip
    headline: str | None = option("the final evaluation block the run is ranked by, e.g. "
                                  "test/paper or episodes (default: train/paper for mazes, "
                                  "episodes for other envs)")
    method_options: dict[str, Any] = field(
        default_factory=dict,
        metadata={"help": "JSON object of the method's options (abco train --method M --help "
                            "lists them; each is a flag of its own too)"},
    )

    def resolved(self, method_defaults: Mapping[str, Any] | None = None) -> RunConfig:
        """A copy with every ``None`` field filled in (:mod:`abco_train.config.defaults`;
        ``method_defaults``: the method's own, last); fields set by the user always win."""
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
            values["run_dir"] = str(Path("runs") / default_run_name(self))
        return RunConfig(**values)

    def validate(self) -> RunConfig:
        """Check every set field (type, choices, bounds) and the rules between fields;
        return ``self``.

        Raises:
            ConfigError: The first field out of range, named as its command-line option.
        """
        kind = env_kind(self.env)
        if self.arch is not None and self.arch in ARCHS and self.arch not in ARCHS_BY_KIND[kind]:
            raise ConfigError(f"--arch {self.arch} does not fit {self.env}'s observations; use "
                              f"{' or '.join(ARCHS_BY_KIND[kind])}")  # fmt: skip
        if kind != "maze" and self.eval_fresh:
            raise ConfigError(f"--eval-fresh is for mazes: {self.env} has no layouts")
        _check_datasets(self)
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
        check_fields(self)
        if self.success is not None:
            parse_success(self.success)
        if self.headline is not None and self.headline not in evaluation_blocks(self):
            raise ConfigError(f"--headline must be one of the final evaluation's blocks "
                              f"({', '.join(evaluation_blocks(self))}), got "
                              f"{self.headline[:60]!r}")  # fmt: skip
        return self

    def to_json(self) -> str:
        """The config as JSON (``config.json`` of a run folder)."""
        return json.dumps(asdict(self), indent=2, sort_keys=True)

    def replace(self, **changes: Any) -> RunConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


def default_run_name(config: RunConfig) -> str:
    """The default run folder's name, ``{env}-{method}[-{preset}][-{regime}][-K{K}]-s{seed}``.

    The preset and regime are named where they are not the defaults, so runs of the same env,
    method and seed under another preset or regime never share a folder; every character but
    letters, digits, ``.``, ``_`` and ``-`` becomes ``_`` (an env ``module:Id`` has a colon,
    which some file systems and tools refuse).

    Example:
        >>> default_run_name(RunConfig(env="AbcoMaze5x5-v0", preset="paper"))
        'AbcoMaze5x5-v0-abco-paper-s0'
        >>> default_run_name(RunConfig(env="corridor:Corridor-v0", method="bco", seed=3))
        'corridor_Corridor-v0-bco-s3'
    """
    parts = [config.env, config.method]
    if config.preset != "cpu":
        parts.append(config.preset)
    if config.regime != "default":
        parts.append(config.regime)
    if config.layouts is not None:
        parts.append(f"K{config.layouts}")
    parts.append(f"s{config.seed}")
    return re.sub(r"[^A-Za-z0-9._-]", "_", "-".join(parts))


def _check_datasets(config: RunConfig) -> None:
    """An env beyond the built-in ones has no datasets of abco's: the run names its own, and
    evaluates under the step limit they were recorded with.

    Raises:
        ConfigError: ``--expert-data`` or ``--pre-data`` missing for such an env, or
            ``--eval-max-steps`` given.
    """
    missing = [(flag, kind) for flag, kind, given in (
        ("--expert-data", "expert", config.expert_data), ("--pre-data", "pre", config.pre_data))
        if given is None]  # fmt: skip
    if is_builtin_env(config.env):
        return
    if missing:
        flag, kind = missing[0]
        raise ConfigError(
            f"{config.env} has no built-in {kind} dataset: record one with abco data record "
            f"--env {config.env} --kind {kind} ... --id local/NAME-v0 and give it as {flag} "
            "(see 'Your own datasets' in docs/datasets.md)")
    if config.eval_max_steps is not None:  # the score's references: the dataset's, uncut
        raise ConfigError(
            f"--eval-max-steps is for the built-in envs: {config.env}'s score references are "
            "its expert dataset's, measured under the env's own step limit; record the "
            "datasets with abco data record --max-episode-steps N to change that limit")


#: Settings that may differ between a run and its resumption (and between a finished grid
#: cell and a re-run of the grid): where things are, how loud, how many threads.
# The datasets (expert_data, pre_data) are part of a run's identity: a finished run asked for
# with other data is another run, not a result to hand back.
RUNTIME_FIELDS = ("quiet", "run_dir", "cache_dir", "threads", "device", "plots", "plot_layouts")


def comparable(config: Mapping[str, Any]) -> dict[str, Any]:
    """The fields of a config (as a dict) that make a run what it is (no runtime fields)."""
    return {k: v for k, v in config.items() if k not in RUNTIME_FIELDS}


# -- command line ---------------------------------------------------------------------------


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
    add_field_options(parser, RunConfig, exclude=exclude, unset_defaults=unset_defaults,
                      shown_default="per env, preset and method (abco_train.config.defaults)")


def config_from_args(args: argparse.Namespace, **fixed: Any) -> RunConfig:
    """The :class:`RunConfig` of parsed options (``None`` options keep the field default)."""
    values: dict[str, Any] = {}
    for f in fields(RunConfig):
        value = fixed.get(f.name, getattr(args, f.name, None))
        if value is not None:
            values[f.name] = value
    return RunConfig(**values)
