"""The interface an imitation-from-observation method implements, and the method registry.

The harness (:func:`abco_train.train.train`) owns everything around a method: the datasets,
seeding, the per-iteration evaluation (whose rollouts it hands back as post-demonstrations),
metrics, checkpoints, plots and resuming. A method only learns and acts.

To plug in another method, subclass :class:`Method` and register it::

    from abco_train.methods import Method, register

    @register("my-ifo")
    class MyIfO(Method):
        def __init__(self, config, data, rng): ...
        def train_iteration(self, iteration): ...   # -> dict of scalars to log
        def act(self, obs): ...                     # batched greedy actions
        def state_dict(self): ...
        def load_state_dict(self, state): ...

then ``abco train --method my-ifo`` (after importing the module that registers it, e.g. with
``--plugin my_package.my_module``) trains and evaluates it exactly like ABCO.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["Method", "register", "get_method", "available"]

_REGISTRY: dict[str, type[Method]] = {}


class Method(ABC):
    """An IfO method trained in iterations ``0..num_iterations-1`` by the harness.

    Per iteration the harness calls :meth:`train_iteration`, then evaluates :meth:`act` on
    the evaluation episodes (with observations and actions recorded), then passes those
    rollouts to :meth:`observe`.

    Args:
        config: The run's :class:`abco_train.abco.Config` (resolved); method-specific options
            go in ``config.method_options``.
        data: The run's :class:`abco_train.abco.TrainingData` (expert states, pre-demos).
        rng: The run's seeded numpy generator; draw all randomness from it (and from torch,
            seeded by the harness) so that a seed fixes the run.
    """

    def __init__(self, config: Any, data: Any, rng: np.random.Generator) -> None:
        self.config, self.data, self.rng = config, data, rng

    @property
    def num_iterations(self) -> int:
        """How many iterations the harness runs (default: ``config.iterations + 1``)."""
        return int(self.config.iterations) + 1

    @abstractmethod
    def train_iteration(self, iteration: int) -> dict[str, float]:
        """Learn for one iteration; return scalars to log."""

    @abstractmethod
    def act(self, obs: np.ndarray) -> np.ndarray:
        """Greedy actions for a batch of observations (one call per environment step)."""

    def observe(self, iteration: int, rollouts: Any) -> dict[str, float]:
        """Take the post-demonstrations (a ``Rollouts``) of ``iteration``."""
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


def get_method(name: str) -> type[Method]:
    """The class registered as ``name``.

    Raises:
        KeyError: Unknown name (the message lists the registered ones).
    """
    import abco_train.abco  # noqa: F401  (registers the built-in variants)

    if name not in _REGISTRY:
        raise KeyError(f"unknown method {name!r}; registered: {', '.join(available())}")
    return _REGISTRY[name]


def available() -> tuple[str, ...]:
    """Registered method names."""
    import abco_train.abco  # noqa: F401

    return tuple(_REGISTRY)
