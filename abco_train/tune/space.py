"""The search space of a method: its run settings (``run_search``) and its options (``search``).

Example:
    >>> sorted(method_space("bc"))
    ['lr', 'patience_checks', 'policy_epochs']
    >>> sorted(method_space("bco", [{"schedule": "converged"}]))  # the epoch counts: unread
    ['lr', 'patience_checks']
    >>> split_params("bco", {"lr": 0.001, "idm_epochs": 8})
    ({'lr': 0.001}, {'idm_epochs': 8})
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from abco_train.bench.tasks import Track
from abco_train.config.fields import Search, search_space
from abco_train.config.run import RunConfig
from abco_train.methods.registry import options_class

__all__ = ["FAMILIES", "method_space", "resolved_options", "suggest", "split_params",
           "describe"]  # fmt: skip

#: The task families a tuning is split by: the env kinds of
#: :func:`~abco_train.config.run.env_kind`.
FAMILIES = ("classic", "maze", "image")


def method_space(method: str, resolved: Sequence[Any] | None = None
                 ) -> dict[str, tuple[Search, type]]:  # fmt: skip
    """What a tuner may change for ``method``: setting name -> (its range, its type); the run
    settings the method reads first, then its own options.

    Args:
        method: A registered method.
        resolved: The method's resolved options on each task tuned together (mappings or
            options objects); a setting none of them reads (its range's ``read_when``) is
            left out. ``None``: every setting with a range.
    """
    cls = options_class(method)
    run, own = search_space(RunConfig), search_space(cls)
    space = {**{name: run[name] for name in cls.run_search},
             **{name: own[name] for name in cls.searched(method)}}  # fmt: skip
    if resolved is None:
        return space
    return {name: (search, kind) for name, (search, kind) in space.items()
            if any(search.reads(options) for options in resolved)}  # fmt: skip


def resolved_options(track: Track, method: str, tasks: Sequence[str]) -> list[Any]:
    """``method``'s resolved options on each of ``track``'s ``tasks`` (a validation seed's
    cell, as a trial runs it): what :func:`method_space` reads its ``read_when`` from."""
    from abco_train.bench.cells import cell_config, parse_seeds, plan_track
    from abco_train.methods.registry import config_from_record, resolve_config

    seed = parse_seeds(track.validation_seeds)[:1] if track.validation_seeds else [0]
    configs = [config_from_record(cell_config(cell, ".", track=track))
               for cell in plan_track(track, list(tasks), [method], seed)]  # fmt: skip
    return [options_class(method).for_run(resolve_config(c), method) for c in configs]


def suggest(trial: Any, space: dict[str, tuple[Search, type]]) -> dict[str, Any]:
    """The settings an Optuna ``trial`` draws from ``space``."""
    return {name: search.suggest(trial, name, kind) for name, (search, kind) in space.items()}


def split_params(method: str, params: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``params`` split into run settings (overrides of every cell) and method options."""
    own = set(options_class(method).names())
    return ({k: v for k, v in params.items() if k not in own},
            {k: v for k, v in params.items() if k in own})  # fmt: skip


def describe(method: str, resolved: Sequence[Any] | None = None) -> str:
    """The method's search space in words (``none``: only its defaults can be tried), on
    the tasks of ``resolved`` (:func:`method_space`)."""
    space = method_space(method, resolved)
    return "; ".join(f"`{n}` {s.describe(k)}" for n, (s, k) in space.items()) or "none"
