"""LAPO's linear probe and DILO's expert weights, read from run folders, as a table and a plot.

Each LAPO run logs ``probe_accuracy`` per round: a linear classifier's held-out accuracy at
telling the true action of pre-demonstrations from their latent codes (whether the latent
model found the actions). Each DILO run logs ``weight_ratio`` per round: the mean weight
``exp(tau V(s, s'))`` of the expert's transitions over the pre-demonstrations' (whether the
utility puts more mass on expert-like transitions). This script gathers both from any grids
or tuning folders and prints a Markdown table per task (mean over seeds of the last round,
with the range) and draws ``--out`` (per task: LAPO's probe against chance, the share of the
largest action of uniform random pre-demonstrations; DILO's ratio per round, one line per seed).

Usage (from the repository root, the development install)::

    .venv/bin/python tools/modern_diagnostics.py TUNING/classic/lapo/trial000 \
        TUNING/classic/dilo/trial000 --out docs/notes/modern-diagnostics.png
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import gymnasium as gym

import abco_envs  # noqa: F401  (registers the mazes with gymnasium)
from abco_train.bench.tasks import load_track
from abco_train.report.runs import Run, load_runs

#: The metric each method's check reads, per round.
CHECKS = {"lapo": "probe_accuracy", "dilo": "weight_ratio"}


def per_round(run: Run, metric: str) -> list[float]:
    """``metric`` of each round of ``run`` that logged it (its ``train`` block or top level)."""
    values = []
    for line in run.metrics():
        block: dict[str, Any] = {**line, **(line.get("train") or {})}
        if isinstance(block.get(metric), (int, float)):
            values.append(float(block[metric]))
    return values


def chance(task: str, envs: dict[str, str]) -> float:
    """The largest action's share under uniform random actions: one over the actions."""
    env = gym.make(envs.get(task, task))
    try:
        return 1.0 / int(env.action_space.n)  # type: ignore[attr-defined]
    finally:
        env.close()


def gather(folders: list[Path]) -> dict[str, dict[str, list[list[float]]]]:
    """``method -> task -> [per-round values of each run]`` over every run of ``folders``."""
    found: dict[str, dict[str, list[list[float]]]] = defaultdict(lambda: defaultdict(list))
    for folder in folders:
        for run in load_runs(folder):
            metric = CHECKS.get(run.method)
            values = per_round(run, metric) if metric else []
            if values:
                found[run.method][run.env].append(values)
    return found


def table(found: dict[str, dict[str, list[list[float]]]], envs: dict[str, str]) -> str:
    """A Markdown table: per method and task, the last round's mean over runs and range."""
    lines = ["| method | metric | task | runs | last round, mean | range | chance |",
             "| --- | --- | --- | ---: | ---: | --- | ---: |"]
    for method, tasks in sorted(found.items()):
        for task, runs in sorted(tasks.items()):
            last = [values[-1] for values in runs]
            floor = f"{chance(task, envs):.2f}" if method == "lapo" else "1 (no preference)"
            lines.append(f"| {method} | {CHECKS[method]} | {task} | {len(last)} | "
                         f"{sum(last) / len(last):.3f} | {min(last):.3f}-{max(last):.3f} | "
                         f"{floor} |")  # fmt: skip
    return "\n".join(lines)


def plot(found: dict[str, dict[str, list[list[float]]]], envs: dict[str, str],
         out: Path) -> None:  # fmt: skip
    """LAPO's probe per task against chance (left) and DILO's ratio per round (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    lapo = sorted(found.get("lapo", {}).items())
    for x, (task, runs) in enumerate(lapo):
        left.scatter([x] * len(runs), [values[-1] for values in runs], color="C0", zorder=3)
        left.hlines(chance(task, envs), x - 0.3, x + 0.3, color="grey", linestyles="dashed")
    left.set_xticks(range(len(lapo)), [task for task, _ in lapo], rotation=20, ha="right")
    left.set(ylim=(0, 1.05), ylabel="held-out probe accuracy",
             title="LAPO: latent codes -> true action (dashes: chance)")
    for colour, (task, runs) in enumerate(sorted(found.get("dilo", {}).items())):
        for i, values in enumerate(runs):
            right.plot(range(1, len(values) + 1), values, color=f"C{colour}", marker="o",
                       label=task if i == 0 else None)  # fmt: skip
    right.axhline(1.0, color="grey", linestyle="dashed")
    right.set(yscale="log", xlabel="round", ylabel="expert / pre-demonstration weight",
              title="DILO: mean weight exp(tau V) on expert transitions")
    right.xaxis.set_major_locator(MaxNLocator(integer=True))
    right.legend(fontsize="small")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, help="grids or tuning trial folders")
    parser.add_argument("--out", type=Path, default=None, help="the plot (PNG); none if left out")
    parser.add_argument("--track", default="headline", help="the track naming the tasks' envs")
    args = parser.parse_args(argv)
    missing = [str(f) for f in args.folders if not f.is_dir()]
    if missing:
        print(f"error: no such folder: {', '.join(missing)}", file=sys.stderr)
        return 2
    envs = {task.name: task.env for task in load_track(args.track).tasks}
    found = gather(args.folders)
    if not found:
        print("error: no LAPO or DILO run with its diagnostics in those folders",
              file=sys.stderr)  # fmt: skip
        return 1
    print(table(found, envs))
    if args.out is not None:
        plot(found, envs, args.out)
        print(f"plot: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
