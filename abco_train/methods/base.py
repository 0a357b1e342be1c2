"""The interface an imitation-from-observation method implements, the registry, the plugins.

The harness (:func:`abco_train.harness.loop.train`) owns everything around a method: the datasets,
seeding, the per-iteration evaluation (whose rollouts it hands back as post-demonstrations),
metrics, checkpoints, plots and resuming. A method only learns and acts. The built-in methods
(:mod:`abco_train.methods.bco.family`) are registered the same way a user's are.

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
steps it takes in an env of its own (:func:`abco_train.harness.rollouts.make_vector_env`).
Evaluation
episodes are never counted. The harness stores the counts with every iteration's metrics, in
checkpoints and in ``final.json``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from abco_train.config.fields import MethodOptions
from abco_train.config.run import RunConfig
from abco_train.harness.training_data import TrainingData

if TYPE_CHECKING:
    from abco_train.harness.rollouts import Rollouts

__all__ = ["Method", "TrainingFailed", "BudgetExceeded", "INTERACTION_KINDS"]

#: Kinds of environment interaction a run may spend (evaluation episodes are not counted):
#: transitions of the pre-demonstrations it trains on, rollout steps it learns from
#: (post-demonstrations), reinforcement-learning steps, and steps that learn an action mapping.
INTERACTION_KINDS = ("pre_demonstration", "post_demonstration", "rl", "remapping")

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


class BudgetExceeded(RuntimeError):
    """A method tried to count more environment interactions than the run's ``--budget``.

    A method plans within :attr:`Method.budget_left` so that this never happens; the harness
    ends a run that raises it with status ``over_budget`` (never a normal-looking result).
    """


class Method(ABC):
    """An IfO method trained in iterations ``0..num_iterations-1`` by the harness.

    Per iteration the harness calls :meth:`train_iteration`, then evaluates :meth:`act` on
    the evaluation episodes, then passes post-demonstrations to :meth:`observe`: the
    evaluation runs themselves (recorded), or, for a method with ``explores = True``, runs of
    the same episodes whose actions come from :meth:`explore` (evaluation stays greedy).

    A method's own settings are a dataclass of :class:`~abco_train.config.fields.MethodOptions`
    named by :attr:`Options`; the harness resolves them (:meth:`resolve_options`: unknown keys
    refused, values checked) and the method reads them typed from ``self.options``.

    Args:
        config: The run's resolved config; the method's resolved options are in
            ``config.method_options`` (as a dict) and ``self.options`` (typed).
        data: The run's datasets (expert states, pre-demonstrations, reference returns).
        rng: The run's seeded numpy generator; draw all randomness from it (and from torch,
            seeded by the harness) so that a seed fixes the run.
    """

    #: Post-demonstrations come from :meth:`explore` rollouts, not from the evaluation runs.
    explores: bool = False
    #: Its iterations learn from interactions of its own (rollouts, RL or remapping steps);
    #: ``False``: an offline method, whose later iterations go on training on the datasets,
    #: so a spent budget does not end its run.
    online: bool = True
    #: The method's options (none by default: every ``--method-options`` key is refused).
    Options: ClassVar[type[MethodOptions]] = MethodOptions

    def __init__(self, config: RunConfig, data: TrainingData, rng: np.random.Generator) -> None:
        self.config, self.data, self.rng = config, data, rng
        #: The run's options, typed (:attr:`Options`).
        self.options = self.resolve_options(config)
        #: Environment interactions spent so far, by kind (:data:`INTERACTION_KINDS`).
        self.interactions: dict[str, int] = dict.fromkeys(INTERACTION_KINDS, 0)

    def count(self, kind: str, steps: int) -> None:
        """Add ``steps`` environment interactions of ``kind`` to the run's cost.

        Raises:
            ValueError: ``kind`` is not one of :data:`INTERACTION_KINDS`.
            BudgetExceeded: The run has a ``--budget`` and this would exceed it (a method plans
                within :attr:`budget_left` instead).
        """
        if kind not in INTERACTION_KINDS:
            raise ValueError(f"unknown interaction kind {kind!r}; expected one of "
                             f"{INTERACTION_KINDS}")  # fmt: skip
        if self.config.budget is not None and self.spent + int(steps) > self.config.budget:
            raise BudgetExceeded(
                f"{kind}: {int(steps):,} more interactions would bring the run to "
                f"{self.spent + int(steps):,}, over its budget of {self.config.budget:,}"
            )
        self.interactions[kind] += int(steps)

    @property
    def spent(self) -> int:
        """Environment interactions counted so far, all kinds summed."""
        return sum(self.interactions.values())

    @property
    def budget_left(self) -> int | None:
        """Interactions the run may still spend (``None``: the run has no ``--budget``)."""
        if self.config.budget is None:
            return None
        return max(0, self.config.budget - self.spent)

    @classmethod
    def defaults(cls, name: str) -> Mapping[str, Any]:
        """Config defaults of the method registered as ``name`` (over the env's; none here)."""
        return {}

    @classmethod
    def fixed(cls, name: str) -> Mapping[str, Any]:
        """Run settings the method always runs with, whatever the config gives: settings its
        networks never read, recorded as it runs (none here)."""
        return {}

    @classmethod
    def resolve_options(cls, config: RunConfig) -> MethodOptions:
        """The run's options (:meth:`MethodOptions.for_run` of :attr:`Options`):
        ``config.method_options`` over the defaults for the run.

        Raises:
            ConfigError: An unknown option or a value that does not fit.
        """
        return cls.Options.for_run(config, config.method)

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

    def learns_from_rollouts(self, iteration: int) -> bool:
        """Whether :meth:`observe` learns from (and counts) ``iteration``'s rollouts: with a
        ``--budget`` the harness then caps them at :attr:`budget_left` steps (default: whether
        the class overrides :meth:`observe`)."""
        return type(self).observe is not Method.observe

    def expert_labels(self) -> np.ndarray | None:
        """Actions the method inferred for the expert transitions (plotted), if any."""
        return None

    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume after the current iteration, as data.

        Data only: tensors (a module's or an optimiser's ``state_dict()``), numpy arrays of
        numbers, bools or strings, Python numbers, strings, bools and ``None``, and lists,
        tuples and dicts of them (a numpy generator's ``bit_generator.state`` is such a dict).
        No objects of other classes: checkpoints are read with
        ``torch.load(weights_only=True)``, which builds nothing else and so runs no code. The
        harness stores numpy arrays as tensors and gives them back as the same arrays (dtype,
        shape, every bit), so a resumed run is the run it would have been.
        """

    @abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`.

        ``state`` comes from a file and may be damaged: raise ``KeyError``, ``TypeError`` or
        ``ValueError`` (a tensor of another size: torch's ``RuntimeError``) on what does not
        fit; the harness refuses the checkpoint in one line.
        """
