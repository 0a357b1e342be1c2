"""Training to convergence: a fit that ends on its own held-out score, not on a step count.

A step or epoch count ties the number of updates to the data's size and, through the
iterations a budget allows, to the budget. A converged fit runs windows of
``check_updates`` updates; after each, the held-out score is measured (higher is better); it
stops once ``patience_checks`` windows in a row brought no better score and at least
``min_updates`` were made, or at ``max_updates``, and keeps the best weights. Every method
with a ``schedule`` option uses it (the BCO family, LAPO); its options are declared once here
(:func:`schedule_option`, :func:`converged_option`) and read by :func:`schedule_of`.

Example:
    >>> import torch
    >>> net = torch.nn.Linear(1, 1)
    >>> scores = iter([0.1, 0.3, 0.2, 0.2, 0.2])
    >>> converge(lambda n: 0.0, lambda: next(scores), [net], Schedule(10, 3, 20, 100))
    {'loss': 0.0, 'updates': 50.0, 'best': 0.3}
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from abco_train.config.fields import Search, option
from abco_train.config.limits import MAX_STEPS

if TYPE_CHECKING:  # the options' modules import this one, and no torch (fast --help)
    import torch

__all__ = ["Schedule", "converge", "held_out_split", "split_rows", "schedule_of", "schedule_option",
           "converged_option", "CONVERGED_DEFAULTS", "HELD_OUT_CAP", "LOSS_GAIN"]  # fmt: skip

#: The most rows a held-out split keeps (a tenth of the data below it).
HELD_OUT_CAP = 2000

#: The relative gain a held-out *loss* must make to count as better (1%).
LOSS_GAIN = 0.01
#: The checks of every method's converged schedule: windows of 100 updates, five windows of
#: patience, 500 to 20,000 updates a fit (the values of the validation study in
#: ``docs/notes/fair-fight.md``).
CONVERGED_DEFAULTS: dict[str, int] = {"check_updates": 100, "patience_checks": 5,
                                      "min_fit_updates": 500, "max_fit_updates": 20_000}

#: What a tuner searches of the schedule, where a run converges: how long a fit waits for a
#: better held-out score (the updates' count of a converged fit is its own, not a setting).
_CONVERGED_SEARCH = {"patience_checks": Search(2, 10, read_when=(("schedule", "converged"),))}

_CONVERGED_HELP = {
    "check_updates": "converged: minibatch updates between held-out checks",
    "patience_checks": "converged: stop after this many checks without a better held-out score",
    "min_fit_updates": "converged: at least this many updates per fit",
    "max_fit_updates": "converged: at most this many updates per fit",
}


@dataclass(frozen=True)
class Schedule:
    """When a converged fit checks, and when it stops."""

    check_updates: int
    patience_checks: int
    min_updates: int
    max_updates: int


def schedule_option(fixed: str, what: str) -> Any:
    """A method's ``schedule`` option: ``fixed`` (its counts, ``what``) or ``converged``."""
    return option(f"how each network's fit ends: {fixed} ({what}) or converged (when its "
                  "held-out score stops improving: check-updates, patience-checks, "
                  "min-fit-updates, max-fit-updates)", choices=(fixed, "converged"))  # fmt: skip


def converged_option(name: str) -> Any:
    """One of the converged schedule's four options (:data:`CONVERGED_DEFAULTS`' names)."""
    search = _CONVERGED_SEARCH.get(name)
    return option(_CONVERGED_HELP[name], min=1, max=MAX_STEPS,
                  **({"search": search} if search else {}))


def schedule_of(options: Any) -> Schedule | None:
    """The options' converged :class:`Schedule`, or ``None`` for their fixed counts."""
    if options.schedule != "converged":
        return None
    return Schedule(int(options.check_updates), int(options.patience_checks),
                    int(options.min_fit_updates), int(options.max_fit_updates))  # fmt: skip


def held_out_split(n: int, seed: int, tag: int) -> tuple[np.ndarray, np.ndarray]:
    """``(train, held-out)`` rows of ``n``: a tenth held out (at least one where ``n > 1``, at
    most :data:`HELD_OUT_CAP`), drawn by the run's generator ``tag`` of its own, so that no
    other draw of the run moves.

    Example:
        >>> train, held = held_out_split(50, seed=0, tag=1)
        >>> len(train), len(held), len(set(train.tolist()) & set(held.tolist()))
        (45, 5, 0)
    """
    from abco_train.harness.runtime import derived_rng

    size = min(HELD_OUT_CAP, max(1, n // 10)) if n > 1 else 0
    order = derived_rng(seed, tag).permutation(n)
    return np.sort(order[size:]), np.sort(order[:size])


def split_rows(n: int, seed: int, tag: int, held_out: bool) -> tuple[Any, Any]:
    """``(train, held-out)`` rows of ``n`` as torch tensors: :func:`held_out_split`'s where
    ``held_out`` (a converged schedule), else every row and none."""
    import torch

    if held_out:
        train, held = held_out_split(n, seed, tag)
    else:
        train, held = np.arange(n), np.zeros(0, dtype=np.int64)
    return torch.from_numpy(train), torch.from_numpy(held)


def converge(window: Callable[[int], float], score: Callable[[], float],
             modules: Sequence[torch.nn.Module], schedule: Schedule,
             min_gain: float = 0.0) -> dict[str, float]:  # fmt: skip
    """Windows of updates until the held-out score stops improving; the best weights kept.

    Args:
        window: Makes that many updates; returns their mean loss.
        score: The held-out score, higher is better (NaN: nothing held out, every window
            counts as better).
        modules: What the fit trains: their states (parameters and buffers) at the best
            score are restored at the end.
        schedule: The checks.
        min_gain: A score counts as better only above ``best + min_gain * |best|``: a
            regression loss keeps improving in its last digits long after it has converged
            (:data:`LOSS_GAIN`); accuracies take 0.

    Returns:
        ``loss`` (the last window's), ``updates`` made, ``best`` held-out score.
    """
    size = max(1, schedule.check_updates)
    best, best_state, stale, updates, loss = -np.inf, None, 0, 0, float("nan")
    while updates < schedule.max_updates:
        step = min(size, schedule.max_updates - updates)
        loss = window(step)
        updates += step
        value = score()
        if np.isnan(value) or best == -np.inf or value > best + min_gain * abs(best):
            best, stale = value, 0
            best_state = [{k: v.detach().clone() for k, v in m.state_dict().items()}
                          for m in modules]  # fmt: skip
        else:
            stale += 1
        if stale >= schedule.patience_checks and updates >= schedule.min_updates:
            break
    if best_state is not None:
        for module, state in zip(modules, best_state):
            module.load_state_dict(state)
    return {"loss": loss, "updates": float(updates), "best": float(best)}
