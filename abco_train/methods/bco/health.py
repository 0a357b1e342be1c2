"""The IDM's health, measured and reported: it never stops a run.

Algorithm 1 of the ABCO paper has no health stop: it returns the policy after its iterations,
and collapsing labels are the failure it measures. So every check here is logged with the
iteration's statistics (``metrics.jsonl``), summed up in ``final.json``'s ``health``
(:func:`abco_train.harness.metrics.health_summary`) and shown by ``abco report``; the run goes
on to its end and is scored like any other.

* ``idm_at_chance``: the IDM's held-out accuracy on pre-demonstrations is below ``chance +
  DEAD_MARGIN`` (chance: the largest action share of the held-out transitions), judged on at
  least ``MIN_JUDGED`` held-out transitions. An IDM re-trained on the policy's own
  post-demonstrations (BCO(α), or ABCO at a win rate of 1) may look at chance on random
  actions while it labels the expert well: its accuracy on its own training set,
  ``idm_train_accuracy``, and the expert labels' spread tell the two apart.
* ``expert_label_entropy``: the entropy of the expert labels' action distribution over
  ``log(n_actions)`` (0: one action for every expert pair, 1: uniform);
  ``expert_labels_one_action``: every expert pair got the same label.

Example:
    >>> import numpy as np
    >>> label_health(np.array([0, 0, 0, 0]), 2)
    {'expert_label_entropy': 0.0, 'expert_labels_one_action': True}
    >>> at_chance(0.52, chance=0.5, judged=1000), at_chance(0.52, chance=0.5, judged=10)
    (True, False)
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["DEAD_MARGIN", "MIN_JUDGED", "at_chance", "label_health"]

#: An IDM whose held-out accuracy is below ``chance + DEAD_MARGIN`` is at chance.
DEAD_MARGIN = 0.05
#: Below this many held-out transitions the accuracy is logged but not judged: on a few dozen
#: transitions (tiny test datasets) chance and a working IDM cannot be told apart.
MIN_JUDGED = 200


def at_chance(accuracy: float, chance: float, judged: int, least: int = MIN_JUDGED) -> bool:
    """Whether a held-out ``accuracy`` over ``judged`` transitions is at ``chance``."""
    return judged >= least and accuracy < chance + DEAD_MARGIN


def label_health(labels: np.ndarray, n_actions: int) -> dict[str, Any]:
    """The spread of the expert labels: their normalised entropy, and whether one action
    labels every pair."""
    if len(labels) == 0 or n_actions < 2:
        return {"expert_label_entropy": float("nan"), "expert_labels_one_action": False}
    shares = np.bincount(labels, minlength=n_actions) / len(labels)
    nonzero = shares[shares > 0]
    entropy = float(-(nonzero * np.log(nonzero)).sum() / np.log(n_actions))
    return {"expert_label_entropy": round(entropy, 6) + 0.0,
            "expert_labels_one_action": bool(len(nonzero) == 1)}
