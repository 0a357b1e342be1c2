"""The interface an imitation-from-observation method implements, the registry, the plugins.

The harness (:func:`abco_train.train.train`) owns everything around a method: the datasets,
seeding, the per-iteration evaluation (whose rollouts it hands back as post-demonstrations),
metrics, checkpoints, plots and resuming. A method only learns and acts. The built-in methods
(:mod:`abco_train.abco`) are registered the same way a user's are.

To plug in another method, subclass :class:`Method` and register it::

    from abco_train.methods import Method, register

    @register("my-ifo")
    class MyIfO(Method):
        def train_iteration(self, iteration): ...   # -> dict of scalars to log
        def act(self, obs): ...                     # batched greedy actions
        def observe(self, iteration, rollouts): ... # optional: post-demonstrations
        def state_dict(self): ...
        def load_state_dict(self, state): ...

then ``abco train --method my-ifo --plugin my_module.py`` (or ``--plugin my_package.module``)
trains and evaluates it exactly like ABCO, and ``abco bench --plugin ...`` runs it in a grid.

Fair comparisons need every run's cost in environment interactions, so a method counts them
(:meth:`Method.count`) by kind (:data:`INTERACTION_KINDS`): pre-demonstration transitions it
trains on, post-demonstration (rollout) steps it learns from, RL steps and action-remapping
steps it takes in an env of its own (:func:`abco_train.evaluate.make_vector_env`). Evaluation
episodes are never counted. The harness stores the counts with every iteration's metrics, in
checkpoints and in ``final.json``.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from abco_train.config import ConfigError, RunConfig
from abco_train.data import TrainingData

if TYPE_CHECKING:
    from abco_train.evaluate import Rollouts

__all__ = ["Method", "register", "get_method", "available", "load_plugins", "resolve_config",
           "PluginError", "TrainingFailed", "BUILTIN_MODULES", "INTERACTION_KINDS"]  # fmt: skip

#: Modules whose import registers the built-in methods (imported on first lookup).
BUILTIN_MODULES = ("abco_train.abco", "abco_train.iupe", "abco_train.ilpo", "abco_train.gaifo")

#: Kinds of environment interaction a run may spend (evaluation episodes are not counted):
#: transitions of the pre-demonstrations it trains on, rollout steps it learns from
#: (post-demonstrations), reinforcement-learning steps, and steps that learn an action mapping.
INTERACTION_KINDS = ("pre_demonstration", "post_demonstration", "rl", "remapping")

_REGISTRY: dict[str, type[Method]] = {}


class TrainingFailed(RuntimeError):
    """A method's own health check failed: the run stops and ends with this status, never
    with a normal-looking result.

    Attributes:
        status: A short name of what failed (e.g. ``idm_at_chance``), the run's status.
        stats: The iteration's statistics up to the failure (logged by the harness).
    """

    def __init__(self, status: str, message: str, stats: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.status, self.stats = status, dict(stats or {})


class PluginError(ImportError):
    """A ``--plugin`` that cannot be imported; the message names it and the reason."""


class Method(ABC):
    """An IfO method trained in iterations ``0..num_iterations-1`` by the harness.

    Per iteration the harness calls :meth:`train_iteration`, then evaluates :meth:`act` on
    the evaluation episodes, then passes post-demonstrations to :meth:`observe`: the
    evaluation runs themselves (recorded), or, for a method with ``explores = True``, runs of
    the same episodes whose actions come from :meth:`explore` (evaluation stays greedy).

    Args:
        config: The run's resolved config; method-specific options are in
            ``config.method_options``.
        data: The run's datasets (expert states, pre-demonstrations, reference returns).
        rng: The run's seeded numpy generator; draw all randomness from it (and from torch,
            seeded by the harness) so that a seed fixes the run.
    """

    #: Post-demonstrations come from :meth:`explore` rollouts, not from the evaluation runs.
    explores: bool = False

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        self.config, self.data, self.rng = config, data, rng
        #: Environment interactions spent so far, by kind (:data:`INTERACTION_KINDS`).
        self.interactions: dict[str, int] = dict.fromkeys(INTERACTION_KINDS, 0)

    def count(self, kind: str, steps: int) -> None:
        """Add ``steps`` environment interactions of ``kind`` to the run's cost.

        Raises:
            ValueError: ``kind`` is not one of :data:`INTERACTION_KINDS`.
        """
        if kind not in INTERACTION_KINDS:
            raise ValueError(f"unknown interaction kind {kind!r}; expected one of "
                             f"{INTERACTION_KINDS}")  # fmt: skip
        self.interactions[kind] += int(steps)

    @classmethod
    def defaults(cls, name: str) -> Mapping[str, Any]:
        """Config defaults of the method registered as ``name`` (over the env's; none here)."""
        return {}

    @property
    def num_iterations(self) -> int:
        """How many iterations the harness runs (default: ``config.iterations + 1``)."""
        return int(self.config.iterations or 0) + 1

    @abstractmethod
    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Learn for one iteration; return scalars to log.

        Raises:
            TrainingFailed: The method found itself broken (e.g. a model at chance); the run
                ends with that status instead of a result.
        """

    @abstractmethod
    def act(self, obs: np.ndarray) -> np.ndarray:
        """Greedy actions for a batch of observations (one call per environment step)."""

    def explore(self, obs: np.ndarray) -> np.ndarray:
        """Actions of the post-demonstration rollouts when ``explores`` (default: greedy)."""
        return self.act(obs)

    def observe(self, iteration: int, rollouts: Rollouts) -> dict[str, float]:
        """Take the post-demonstrations of ``iteration`` (recorded runs; see the class doc).

        A method that learns from them counts their steps as ``post_demonstration``."""
        return {}

    def expert_labels(self) -> np.ndarray | None:
        """Actions the method inferred for the expert transitions (plotted), if any."""
        return None

    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume after the current iteration (picklable)."""

    @abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`."""


def register(*names: str) -> Callable[[type[Method]], type[Method]]:
    """Class decorator: make a :class:`Method` available under ``names``."""

    def decorate(cls: type[Method]) -> type[Method]:
        for name in names:
            _REGISTRY[name] = cls
        return cls

    return decorate


def _builtins() -> None:
    for module in BUILTIN_MODULES:
        importlib.import_module(module)


def get_method(name: str) -> type[Method]:
    """The class registered as ``name``.

    Raises:
        ConfigError: Unknown name (the message lists the registered ones).
    """
    _builtins()
    if name not in _REGISTRY:
        raise ConfigError(f"unknown method {name!r}; registered: {', '.join(available())}"
                          " (a --plugin may register more)")  # fmt: skip
    return _REGISTRY[name]


def available() -> tuple[str, ...]:
    """Registered method names."""
    _builtins()
    return tuple(_REGISTRY)


def resolve_config(config: RunConfig) -> RunConfig:
    """``config`` validated, with every default filled in, the method's own included.

    Raises:
        ConfigError: A bad setting, unknown env or unknown method.
    """
    config.validate()
    return config.resolved(get_method(config.method).defaults(config.method)).validate()


def load_plugins(plugins: Sequence[str]) -> None:
    """Import each plugin: a ``.py`` file path or a module name (``my_pkg.my_method``).

    Importing a plugin registers its methods (:func:`register`). A file is imported once, as
    module ``abco_plugin_{stem}``.

    Raises:
        PluginError: A missing file or module, or one that fails to import (the message
            names it and the reason; the original exception is chained).
    """
    for plugin in plugins:
        if plugin.endswith(".py") or Path(plugin).is_file():
            path = Path(plugin).resolve()
            if not path.is_file():
                raise PluginError(f"plugin file {plugin} does not exist")
            name = f"abco_plugin_{path.stem}"
            if name in sys.modules:
                continue
            spec = importlib.util.spec_from_file_location(name, path)
            if spec is None or spec.loader is None:
                raise PluginError(f"cannot import plugin file {plugin}")
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            try:
                spec.loader.exec_module(module)
            except Exception as exc:
                del sys.modules[name]
                raise PluginError(f"plugin {plugin} failed to import: "
                                  f"{type(exc).__name__}: {exc}") from exc  # fmt: skip
        else:
            try:
                importlib.import_module(plugin)
            except ModuleNotFoundError as exc:
                raise PluginError(f"plugin module {plugin!r} not found ({exc})") from exc
