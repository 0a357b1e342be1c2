"""The search space of a method: its run settings (``run_search``) and its options (``search``).

Example:
    >>> sorted(method_space("bco")), sorted(method_space("bc"))
    (['idm_epochs', 'idm_patience', 'lr', 'policy_epochs'], ['lr', 'policy_epochs'])
    >>> split_params("bco", {"lr": 0.001, "idm_epochs": 8})
    ({'lr': 0.001}, {'idm_epochs': 8})
"""

from __future__ import annotations

from typing import Any

from abco_train.config.fields import Search, search_space
from abco_train.config.run import RunConfig
from abco_train.methods.registry import options_class

__all__ = ["FAMILIES", "method_space", "suggest", "split_params", "describe"]

#: The task families a tuning is split by: the env kinds of
#: :func:`~abco_train.config.run.env_kind`.
FAMILIES = ("classic", "maze", "image")


def method_space(method: str) -> dict[str, tuple[Search, type]]:
    """What a tuner may change for ``method``: setting name -> (its range, its type); the run
    settings the method reads first, then its own options."""
    cls = options_class(method)
    run, own = search_space(RunConfig), search_space(cls)
    return {**{name: run[name] for name in cls.run_search},
            **{name: own[name] for name in cls.searched(method)}}  # fmt: skip


def suggest(trial: Any, space: dict[str, tuple[Search, type]]) -> dict[str, Any]:
    """The settings an Optuna ``trial`` draws from ``space``."""
    return {name: search.suggest(trial, name, kind) for name, (search, kind) in space.items()}


def split_params(method: str, params: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``params`` split into run settings (overrides of every cell) and method options."""
    own = set(options_class(method).names())
    return ({k: v for k, v in params.items() if k not in own},
            {k: v for k, v in params.items() if k in own})  # fmt: skip


def describe(method: str) -> str:
    """The method's search space in words (``none``: only its defaults can be tried)."""
    space = method_space(method)
    return "; ".join(f"`{n}` {s.describe(k)}" for n, (s, k) in space.items()) or "none"
