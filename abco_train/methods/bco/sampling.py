"""ABCO's win/loss sampling of the IDM's training set ``I_s`` (Eqs. 4-6 of the paper).

The formula, where the paper is loose (this is what :func:`sample_training_set` does):

* ``N = size`` is the size of ``I_s`` every iteration (default: ``|I_pre|``, the size of
  ``I_s`` at iteration 0, so ``I_s`` keeps one size throughout).
* ``w = P(g | E)`` is the win rate of the **latest** evaluation's runs.
* Post-demonstrations: Eq. 4's ``P(A | E; I_pos) = sum_e v_e P(A | e) / |E|`` sums to ``w``;
  normalised, ``q_c = sum_e v_e P(c | e) / sum_e v_e`` is the per-run average action
  distribution of the winning runs (each winning run weighs the same, whatever its length).
  Eq. 5 then draws ``n_pos_c = round(N * w * q_c)`` transitions of class ``c`` (**per-class**
  sizes) uniformly from the winning runs' transitions of class ``c``. With ``mode="whole"``
  (the paper's "whole sampling" ablation) every run counts as winning for ``q`` and the
  pool, but the size is still ``N * w``.
* Pre-demonstrations (Eq. 6): ``n_pre_c = round(N * (1 - w) * p_c)`` with ``p_c`` the share of
  class ``c`` in ``I_pre``, drawn uniformly from ``I_pre``'s transitions of class ``c``.
* Rounding: the per-class sizes are rounded with the largest-remainder method, so they sum
  to exactly ``round(N * w)`` and ``N - round(N * w)``.
* Draws within a class are uniform, without replacement where the class holds enough
  transitions and with replacement only where it holds fewer than asked. They come from the
  caller's ``numpy.random.Generator``, so a seed fixes them.

Whether ``I_pos`` accumulates over iterations or is replaced is the caller's choice; the
trainer (:mod:`abco_train.methods.bco.family`) passes the accumulated post-demonstrations of all
iterations
and the win rate of the latest one (see its docstring).

Example:
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> pre = np.array([0, 1, 2, 3] * 25)
    >>> pos = np.array([1, 1, 2, 2, 0, 3])
    >>> run = np.array([0, 0, 0, 0, 1, 1])
    >>> s = sample_training_set(pre, pos, run, wins=np.array([True, False]), size=40, rng=rng)
    >>> len(s.pre_indices), len(s.pos_indices), sorted(set(pos[s.pos_indices].tolist()))
    (20, 20, [1, 2])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Sample",
    "largest_remainder",
    "draw_by_class",
    "run_action_distribution",
    "sample_training_set",
]

SAMPLING_MODES = ("partial", "whole")


@dataclass(frozen=True)
class Sample:
    """Indices making up ``I_s``.

    Attributes:
        pre_indices: Indices into the pre-demonstration transitions.
        pos_indices: Indices into the post-demonstration transitions.
        win_rate: ``P(g | E)`` used for the sizes.
        pos_class_shares: ``q_c`` (zeros when no run counts).
    """

    pre_indices: np.ndarray
    pos_indices: np.ndarray
    win_rate: float
    pos_class_shares: np.ndarray


def largest_remainder(total: int, shares: np.ndarray) -> np.ndarray:
    """Integer sizes proportional to ``shares`` that sum to exactly ``total``.

    Example:
        >>> largest_remainder(10, np.array([1.0, 1.0, 1.0])).tolist()
        [4, 3, 3]
    """
    shares = np.asarray(shares, dtype=np.float64)
    if total <= 0 or shares.sum() <= 0:
        return np.zeros(len(shares), dtype=np.int64)
    exact = total * shares / shares.sum()
    sizes = np.floor(exact).astype(np.int64)
    rest = total - int(sizes.sum())
    order = np.argsort(-(exact - sizes), kind="stable")
    sizes[order[:rest]] += 1
    return sizes


def draw_by_class(
    labels: np.ndarray, counts: np.ndarray, rng: np.random.Generator, pool: np.ndarray | None = None
) -> np.ndarray:
    """Draw ``counts[c]`` indices whose label is ``c``, uniformly within each class.

    Args:
        labels: Class of every row.
        counts: Rows wanted per class.
        rng: The generator of the draws.
        pool: Restrict the draw to these row indices (default: all rows).

    Returns:
        The drawn row indices, class by class. Without replacement where a class has enough
        rows, with replacement where it has fewer than asked; a class with no rows gives none.
    """
    labels = np.asarray(labels)
    pool = np.arange(len(labels)) if pool is None else np.asarray(pool, dtype=np.int64)
    drawn = []
    for c, want in enumerate(np.asarray(counts, dtype=np.int64)):
        members = pool[labels[pool] == c]
        if want <= 0 or len(members) == 0:
            continue
        replace = len(members) < want
        drawn.append(rng.choice(members, size=int(want), replace=replace))
    return np.concatenate(drawn) if drawn else np.zeros(0, dtype=np.int64)


def run_action_distribution(
    actions: np.ndarray, run_ids: np.ndarray, runs: np.ndarray, n_actions: int
) -> np.ndarray:
    """``sum_{e in runs} P(A | e) / |runs|``: the per-run average action distribution."""
    if len(runs) == 0:
        return np.zeros(n_actions)
    total = np.zeros(n_actions)
    for e in runs:
        acts = actions[run_ids == e]
        if len(acts):
            total += np.bincount(acts, minlength=n_actions)[:n_actions] / len(acts)
    return total / len(runs)


def sample_training_set(
    pre_actions: np.ndarray,
    pos_actions: np.ndarray,
    pos_run_ids: np.ndarray,
    wins: np.ndarray,
    size: int,
    rng: np.random.Generator,
    mode: str = "partial",
    win_rate: float | None = None,
    n_actions: int | None = None,
) -> Sample:
    """Build ``I_s`` from ``I_pre`` and ``I_pos`` as in the module docstring.

    Args:
        pre_actions: Action of every pre-demonstration transition.
        pos_actions: Action of every post-demonstration transition.
        pos_run_ids: Run of every post-demonstration transition (indices into ``wins``).
        wins: ``v_e`` of every run.
        size: ``N``, the size of ``I_s``.
        rng: Generator of the draws.
        mode: ``"partial"`` (winning runs only; ABCO) or ``"whole"`` (every run).
        win_rate: ``P(g | E)``; defaults to the mean of ``wins``. The trainer passes the win
            rate of the latest evaluation when ``wins`` spans several iterations.
        n_actions: Number of action classes (default: from the labels).
    """
    if mode not in SAMPLING_MODES:
        raise ValueError(f"unknown sampling mode {mode!r}; expected one of {SAMPLING_MODES}")
    pre_actions, pos_actions = np.asarray(pre_actions), np.asarray(pos_actions)
    pos_run_ids, wins = np.asarray(pos_run_ids), np.asarray(wins, dtype=bool)
    if n_actions is None:
        n_actions = int(max(pre_actions.max(initial=-1), pos_actions.max(initial=-1)) + 1)
    w = float(wins.mean()) if win_rate is None and len(wins) else float(win_rate or 0.0)
    counted = np.flatnonzero(wins) if mode == "partial" else np.arange(len(wins))
    if len(counted) == 0:
        w = 0.0
    q = run_action_distribution(pos_actions, pos_run_ids, counted, n_actions)
    q = q / q.sum() if q.sum() > 0 else q
    n_pos = int(round(size * w))
    pos_counts = largest_remainder(n_pos, q)
    pool = np.flatnonzero(np.isin(pos_run_ids, counted))
    pos_idx = draw_by_class(pos_actions, pos_counts, rng, pool)

    p = np.bincount(pre_actions, minlength=n_actions)[:n_actions].astype(np.float64)
    pre_counts = largest_remainder(size - n_pos, p)
    pre_idx = draw_by_class(pre_actions, pre_counts, rng)
    return Sample(pre_idx, pos_idx, w, q)
