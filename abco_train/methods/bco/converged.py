"""The converged schedule of the BCO family (``schedule="converged"``): each network trains
until its own held-out score stops improving, not for a number of epochs.

Epoch counts tie the number of updates to the data's size and, through the iterations a
budget allows, to the budget: Acrobot's IDM on 4,500 transitions made 27-108 updates. Here a
fit runs windows of ``check_updates`` minibatch updates; after each, the held-out score is
measured; the fit stops once ``patience_checks`` windows in a row brought no better score (and
at least ``min_fit_updates`` were made), or at ``max_fit_updates``; the best weights are kept.
The held-out scores: the IDM's accuracy on its held-out pre-demonstrations (true actions);
the policy's agreement with its labels on a fixed held-out tenth of the expert's transitions
(:func:`expert_split`), on which it does not train.

Example:
    >>> train, held = expert_split(50, seed=0)
    >>> len(train), len(held), len(set(train.tolist()) & set(held.tolist()))
    (45, 5, 0)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from abco_train.harness.runtime import derived_rng
from abco_train.methods.bco.fitting import VALIDATION_CAP, fit

__all__ = ["Schedule", "fit_converged", "expert_split"]

#: The expert split's own stream (:func:`abco_train.harness.runtime.derived_rng`).
EXPERT_SPLIT_TAG = 0x2E


@dataclass(frozen=True)
class Schedule:
    """When a converged fit checks, and when it stops."""

    check_updates: int
    patience_checks: int
    min_updates: int
    max_updates: int


def expert_split(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(train, held-out)`` rows of ``n`` expert transitions: a tenth held out (at least one
    where ``n > 1``, at most :data:`~abco_train.methods.bco.fitting.VALIDATION_CAP`), drawn by
    a generator of its own so that no other draw of the run moves."""
    size = min(VALIDATION_CAP, max(1, n // 10)) if n > 1 else 0
    order = derived_rng(seed, EXPERT_SPLIT_TAG).permutation(n)
    return np.sort(order[size:]), np.sort(order[:size])


def fit_converged(net: torch.nn.Module, opt: torch.optim.Optimizer, inputs: Any,
                  labels: torch.Tensor, score: Callable[[], float], schedule: Schedule,
                  batch_size: int, rng: np.random.Generator, **fit_kwargs: Any
                  ) -> dict[str, float]:  # fmt: skip
    """Windows of :func:`~abco_train.methods.bco.fitting.fit` until ``score()`` (held out,
    higher is better; NaN: nothing held out, every window counts as better) stops improving.

    Returns:
        ``loss`` (the last window's mean), ``updates`` made, ``best`` held-out score.
    """
    per_epoch = max(1, -(-len(labels) // batch_size))
    window = max(1, schedule.check_updates)
    best, best_state, stale, updates, loss = -np.inf, None, 0, 0, float("nan")
    while updates < schedule.max_updates:
        step = min(window, schedule.max_updates - updates)
        loss = fit(net, opt, inputs, labels, -(-step // per_epoch), batch_size, rng,
                   max_batches=step, **fit_kwargs)  # fmt: skip
        updates += step
        value = score()
        if np.isnan(value) or value > best:
            best, stale = value, 0
            best_state = {k: v.detach().clone() for k, v in net.state_dict().items()}
        else:
            stale += 1
        if stale >= schedule.patience_checks and updates >= schedule.min_updates:
            break
    if best_state is not None:
        net.load_state_dict(best_state)
    return {"loss": loss, "updates": float(updates), "best": float(best)}
