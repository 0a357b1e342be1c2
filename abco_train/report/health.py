"""The runs a health check flagged: they ran to their end and are scored like the others,
and the report says where the checks fired (``final.json``'s ``health``,
:func:`abco_train.harness.metrics.health_summary`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from abco_train.bench.records import escape

__all__ = ["flagged_lines"]


def _flags(final: dict[str, Any] | None) -> dict[str, list[int]]:
    """A record's flagged checks -> their iterations (a record from elsewhere: what fits)."""
    health = (final or {}).get("health")
    if not isinstance(health, dict):
        return {}
    return {str(name): [i for i in its if isinstance(i, int)] for name, its in health.items()
            if isinstance(its, list) and its}  # fmt: skip


def flagged_lines(runs: Sequence[Any]) -> list[str]:
    """One line per (task or env, method, check): the seeds whose runs the check flagged.

    Example:
        >>> from types import SimpleNamespace as Run
        >>> run = Run(env="Acrobot-v1", method="bco-alpha", seed=1, row={},
        ...           final={"health": {"idm_at_chance": [1, 2], "one_action_labels": []}})
        >>> flagged_lines([run])
        ['- Acrobot-v1 / bco-alpha: idm_at_chance on seed 1']
    """
    seeds: dict[tuple[str, str, str], list[int]] = {}
    for r in runs:
        where = (r.final or {}).get("task") or r.env
        for name in _flags(r.final):
            seeds.setdefault((escape(str(where)), r.method, escape(name)), []).append(r.seed)
    return [f"- {where} / {method}: {name} on seed{'s' * (len(s) > 1)} "
            f"{', '.join(map(str, sorted(s)))}" for (where, method, name), s in seeds.items()]
