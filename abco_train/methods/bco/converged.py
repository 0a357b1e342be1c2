"""The converged schedule of the BCO family (``schedule="converged"``): each network trains
until its own held-out score stops improving (:mod:`abco_train.methods.converged`), not for a
number of epochs.

Epoch counts tie the number of updates to the data's size and, through the iterations a
budget allows, to the budget: Acrobot's IDM on 4,500 transitions made 27-108 updates. The
held-out scores: the IDM's accuracy on its held-out pre-demonstrations (true actions); the
policy's agreement with its labels on a fixed held-out tenth of the expert's transitions
(:func:`expert_split`), on which it does not train.

Example:
    >>> train, held = expert_split(50, seed=0)
    >>> len(train), len(held), len(set(train.tolist()) & set(held.tolist()))
    (45, 5, 0)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from abco_train.methods.bco.fitting import fit
from abco_train.methods.converged import Schedule, converge, held_out_split

__all__ = ["Schedule", "fit_converged", "expert_split"]

#: The expert split's own stream (:func:`abco_train.harness.runtime.derived_rng`).
EXPERT_SPLIT_TAG = 0x2E


def expert_split(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``(train, held-out)`` rows of ``n`` expert transitions
    (:func:`~abco_train.methods.converged.held_out_split` on a stream of their own)."""
    return held_out_split(n, seed, EXPERT_SPLIT_TAG)


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

    def window(step: int) -> float:
        return fit(net, opt, inputs, labels, -(-step // per_epoch), batch_size, rng,
                   max_batches=step, **fit_kwargs)  # fmt: skip

    return converge(window, score, [net], schedule)
