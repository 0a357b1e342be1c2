"""The paper's metrics: AER, Performance ``P`` (per episode, then averaged) and success rate.

``P`` of one episode is ``(R - random) / (expert - random)`` where ``random`` and ``expert``
are the mean returns of the random policy and of the expert *on that episode's setting*: for
mazes the layout played (as the authors computed it, per maze), for classic control the
environment. The reported ``P`` is the mean over episodes.

Reference returns come from the expert dataset (``Dataset.reference``: per layout of the
``train`` and ``test`` splits for mazes, one pair per environment otherwise), always measured
under the environment's own rules (1000-step cap), whatever the evaluation protocol.

A run's health checks, logged per iteration, are summed up for ``final.json`` by
:func:`health_summary`.

Example:
    >>> import numpy as np
    >>> performance(np.array([1.0, 0.5, 0.0]), expert=np.array([1.0, 1.0, 2.0]), random=0.0)
    array([1. , 0.5, 0. ])
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["performance", "summarize", "health_summary", "HEALTH_FLAGS"]


def performance(returns: np.ndarray, expert: Any, random: Any) -> np.ndarray:
    """Per-episode ``P = (R - random) / (expert - random)`` (references broadcast)."""
    returns = np.asarray(returns, dtype=np.float64)
    expert = np.broadcast_to(np.asarray(expert, dtype=np.float64), returns.shape)
    random = np.broadcast_to(np.asarray(random, dtype=np.float64), returns.shape)
    gap = expert - random
    if np.any(np.abs(gap) < 1e-12):
        raise ValueError("expert and random reference returns coincide: P is undefined")
    return (returns - random) / gap


def summarize(
    returns: np.ndarray, successes: np.ndarray, expert: Any, random: Any
) -> dict[str, float]:
    """``{"aer", "performance", "success_rate", "episodes"}`` of a set of episodes."""
    returns = np.asarray(returns, dtype=np.float64)
    return {
        "aer": float(returns.mean()),
        "performance": float(performance(returns, expert, random).mean()),
        "success_rate": float(np.asarray(successes, dtype=np.float64).mean()),
        "episodes": int(len(returns)),
    }


#: The health checks a method logs as ``True`` in an iteration's statistics -> their name in
#: ``final.json``'s ``health`` (:mod:`abco_train.methods.bco.health`).
HEALTH_FLAGS = {"idm_at_chance": "idm_at_chance", "expert_labels_one_action": "one_action_labels"}


def health_summary(history: Sequence[dict[str, Any]]) -> dict[str, list[int]]:
    """``final.json``'s ``health``: the iterations each check flagged (empty: none did). The
    checks report; they never stop a run.

    Example:
        >>> health_summary([{"iteration": 0, "train": {"idm_at_chance": False}},
        ...                 {"iteration": 1, "train": {"idm_at_chance": True}}])
        {'idm_at_chance': [1], 'one_action_labels': []}
    """
    summary: dict[str, list[int]] = {name: [] for name in HEALTH_FLAGS.values()}
    for record in history:
        stats = record.get("train") or {}
        for key, name in HEALTH_FLAGS.items():
            if stats.get(key) is True:
                summary[name].append(int(record["iteration"]))
    return summary
