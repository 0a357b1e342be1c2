"""How many seeds a grid needs: the width of each method's mean-score 95% interval, predicted
from a finished grid's spread of scores for other numbers of seeds per task.

The headline's mean score weighs every task the same (:mod:`abco_train.report.balanced`), so
its standard error is ``sqrt(sum_t var_t / n_t) / tasks``, ``var_t`` a task's variance over
its runs and ``n_t`` its seeds. This script reads a grid's ``results.jsonl`` (a run without a
headline score counts 0, as in the report), takes each task's variance from its runs and
prints, per method, the normal interval's width for the seeds asked (``--seeds task=n``,
``--default n`` for the rest) beside the grid's own seeds, and the width the report's
percentile bootstrap gives on grids of that size drawn from the grid's runs (the mean of
``--draws`` of them), against the goal of 0.10.

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

#: The width of a method's mean-score 95% interval that the headline aims at.
GOAL = 0.10
#: Rows that are references, not methods.
REFERENCES = {"random", "expert"}


def scores(results: Path) -> dict[str, dict[str, list[float]]]:
    """``method -> task -> headline scores`` of a grid's ``results.jsonl`` (0 where none)."""
    out: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for line in results.read_text().splitlines():
        row = json.loads(line)
        final = row.get("final") or {}
        block = final.get(final.get("headline") or "")
        score = block.get("score") if isinstance(block, dict) else None
        out[row["method"]][row["task"]].append(0.0 if score is None else float(score))
    return out


def normal_width(by_task: dict[str, list[float]], seeds: dict[str, int]) -> float:
    """The normal 95% interval's width of the mean over tasks with ``seeds[task]`` runs."""
    variance = sum(np.var(x, ddof=1) / seeds[t] for t, x in by_task.items())
    return float(2 * 1.96 * np.sqrt(variance) / len(by_task))


def bootstrap_width(by_task: dict[str, list[float]], seeds: dict[str, int], draws: int,
                    rng: np.random.Generator) -> float:  # fmt: skip
    """The report's bootstrap interval's mean width over ``draws`` grids drawn from the runs."""
    widths = []
    for i in range(draws):
        columns = [rng.choice(np.asarray(x), size=seeds[t]) for t, x in by_task.items()]
        low, high = balanced.interval(lambda *c: np.array([balanced.mean(c)]), columns,
                                      reps=500, seed=i)  # fmt: skip
        widths.append(float(high[0] - low[0]))
    return float(np.mean(widths))


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
    print(f"{'method':18s} {'its seeds':>9s} {'asked':>6s} {'asked, bootstrap':>16s}")
    for method, by_task in sorted(grid.items()):
        if method in REFERENCES:
            continue
        asked = {t: own.get(t, default) for t in by_task}
        have = {t: len(x) for t, x in by_task.items()}
        now, then = normal_width(by_task, have), normal_width(by_task, asked)
        boot = bootstrap_width(by_task, asked, args.draws, rng)
        flag = "" if max(then, boot) <= GOAL else f"  over {GOAL}"
        print(f"{method:18s} {now:9.3f} {then:6.3f} {boot:16.3f}{flag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
