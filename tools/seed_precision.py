"""How many seeds a grid needs: the width of each method's 95% intervals of its mean score
and its IQM, predicted from a finished grid's spread of scores for other numbers of seeds.

The headline's aggregates weigh every task the same (:mod:`abco_train.report.balanced`), so
the mean's standard error is ``sqrt(sum_t var_t / n_t) / tasks``, ``var_t`` a task's variance
over its runs and ``n_t`` its seeds. This script reads a grid's ``results.jsonl`` as the
report does (a run's headline score floored at 0, ``SCORE_FLOOR``; a run without a score left
out) and prints, per method, the mean's normal interval width with the grid's own seeds and
with the seeds asked (``--seeds task=n``, ``--default n`` for the rest), and the widths the
report's percentile bootstrap gives, for the mean and the IQM, on grids of the size asked
drawn from the grid's runs (the average of ``--draws`` of them). The v2 headline's goal is a
mean-score interval at most 0.10 wide; the IQM's, wider, is printed beside it.

Usage::

    .venv/bin/python tools/seed_precision.py docs/results/headline/runs --default 20 \\
        --seeds maze3x3-heldout=10,maze5x5-heldout=10,maze10x10-authors-regime=10
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from abco_train.report import balanced
from abco_train.report.ranking import SCORE_FLOOR

#: The width of a method's mean-score 95% interval that the headline aims at.
GOAL = 0.10
#: Rows that are references, not methods.
REFERENCES = {"random", "expert"}


def scores(results: Path) -> dict[str, dict[str, list[float]]]:
    """``method -> task -> headline scores`` of a grid's ``results.jsonl``, floored at
    ``SCORE_FLOOR`` as the report's aggregates are; a run without a score is left out."""
    out: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for line in results.read_text().splitlines():
        row = json.loads(line)
        final = row.get("final") or {}
        block = final.get(final.get("headline") or "")
        score = block.get("score") if isinstance(block, dict) else None
        if score is not None and row.get("task"):
            out[row["method"]][row["task"]].append(max(float(score), SCORE_FLOOR))
    return out


def normal_width(by_task: dict[str, list[float]], seeds: dict[str, int]) -> float:
    """The normal 95% interval's width of the mean over tasks with ``seeds[task]`` runs."""
    variance = sum(np.var(x, ddof=1) / seeds[t] for t, x in by_task.items())
    return float(2 * 1.96 * np.sqrt(variance) / len(by_task))


def bootstrap_widths(by_task: dict[str, list[float]], seeds: dict[str, int], draws: int,
                     rng: np.random.Generator) -> tuple[float, float]:  # fmt: skip
    """The report's bootstrap intervals' mean widths, of the mean and of the IQM, over
    ``draws`` grids of ``seeds`` runs a task drawn from the runs."""
    widths = []
    for i in range(draws):
        columns = [rng.choice(np.asarray(x), size=seeds[t]) for t, x in by_task.items()]
        low, high = balanced.interval(
            lambda *c: np.array([balanced.mean(c), balanced.iqm(c)]), columns, reps=500,
            seed=i)  # fmt: skip
        widths.append(high - low)
    mean_width, iqm_width = np.mean(widths, axis=0)
    return float(mean_width), float(iqm_width)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("runs", type=Path, help="a grid's folder (its results.jsonl)")
    parser.add_argument("--default", type=int, default=20, help="seeds of a task not named")
    parser.add_argument("--seeds", default="", help="task=n,... (a task's own seeds)")
    parser.add_argument("--draws", type=int, default=20, help="bootstrapped grids a method")
    args = parser.parse_args(argv)
    results = args.runs / "results.jsonl"
    if not results.is_file():
        print(f"seed_precision: no results.jsonl in {args.runs}", file=sys.stderr)
        return 2
    try:
        own = {t: int(n) for t, n in (item.split("=") for item in args.seeds.split(",") if item)}
    except ValueError:
        parser.error(f"--seeds wants task=n,... (got {args.seeds!r})")
    grid, rng, default = scores(results), np.random.default_rng(0), int(args.default)
    tasks = {t for by_task in grid.values() for t in by_task}
    if unknown := sorted(set(own) - tasks):
        parser.error(f"--seeds names tasks the grid lacks: {', '.join(unknown)}")
    if min([default, *own.values()]) < 2:
        parser.error("a task needs at least 2 seeds for an interval")
    print(f"{'method':18s} {'mean, its seeds':>15s} {'mean':>6s} {'bootstrap':>9s} "
          f"{'IQM, its seeds':>14s} {'IQM':>6s}")
    for method, by_task in sorted(grid.items()):
        if method in REFERENCES or any(len(x) < 2 for x in by_task.values()):
            continue
        asked = {t: own.get(t, default) for t in by_task}
        have = {t: len(x) for t, x in by_task.items()}
        now, then = normal_width(by_task, have), normal_width(by_task, asked)
        _, iqm_now = bootstrap_widths(by_task, have, args.draws, rng)
        boot, iqm_then = bootstrap_widths(by_task, asked, args.draws, rng)
        flag = "" if max(then, boot) <= GOAL else f"  mean over {GOAL}"
        print(f"{method:18s} {now:15.3f} {then:6.3f} {boot:9.3f} {iqm_now:14.3f} "
              f"{iqm_then:6.3f}{flag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
