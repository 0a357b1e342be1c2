"""Plots of the benchmark track: every task's scores, and the IfO methods' aggregates.

* :func:`plot_task_scores`: one panel per task, each method's mean score over seeds with its
  95% bootstrap interval (the figures of the task tables), the scale's 0 (random) and 1
  (the expert) drawn as lines. Cells shown with the paper's P (older records) are left out:
  P is not on the score's scale.
* :func:`plot_aggregates`: IQM and optimality gap of the IfO methods with their stratified
  bootstrap intervals (the aggregate table's figures), drawn by
  ``rliable.plot_utils.plot_interval_estimates``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from abco_train.harness.plots import pyplot, save_figure
from abco_train.report.headline import Cell, role
from abco_train.report.runs import method_order

__all__ = ["TASKS_PNG", "AGGREGATES_PNG", "plot_task_scores", "plot_aggregates"]

TASKS_PNG = "headline_tasks.png"
AGGREGATES_PNG = "headline_aggregates.png"
#: Panels per row of the task plot.
COLUMNS = 4
#: ``(point, low, high)``.
Interval = tuple[float, float, float]
#: Colour by role (:func:`~abco_train.report.headline.role`): IfO methods in colour, the
#: scale's ends in light grey, the true-action reference and other methods in dark grey.
COLOURS = {"IfO": "tab:blue", "reference": "silver"}
OTHER_COLOUR = "dimgrey"


def plot_task_scores(cells: Mapping[str, Mapping[str, Cell]], labels: Mapping[str, str],
                     path: Path) -> Path | None:  # fmt: skip
    """Each task's methods (rows, in the tables' method order) by mean score with its 95%
    interval; ``None`` when no cell has a score."""
    shown = {task: {m: c for m, c in by_method.items() if c.scored and c.stats}
             for task, by_method in cells.items()}  # fmt: skip
    shown = {task: by_method for task, by_method in shown.items() if by_method}
    if not shown:
        return None
    methods = method_order({m for by_method in shown.values() for m in by_method})
    cols = min(len(shown), COLUMNS)
    rows = math.ceil(len(shown) / cols)
    plt = pyplot()
    fig, axes = plt.subplots(rows, cols, squeeze=False, sharey=True,
                             figsize=(3.0 * cols, (0.28 * len(methods) + 1.0) * rows))  # fmt: skip
    for ax, (task, by_method) in zip(axes.flat, shown.items()):
        for row, method in enumerate(methods):
            stats = by_method[method].stats if method in by_method else None
            if stats is None:
                continue
            low, high = stats.ci
            colour = COLOURS.get(role(method), OTHER_COLOUR)
            ax.errorbar(stats.mean, row, xerr=[[stats.mean - low], [high - stats.mean]],
                        fmt="o", ms=4, capsize=2, color=colour)  # fmt: skip
        for end in (0.0, 1.0):
            ax.axvline(end, color="grey", ls=":", lw=1)
        ax.set_title(task, fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0, 0].set_yticks(range(len(methods)), [labels.get(m, m) for m in methods])
    axes[0, 0].invert_yaxis()
    for ax in axes.flat[len(shown):]:
        ax.set_visible(False)
    fig.supxlabel("score (0 random, 1 expert)", fontsize=8)
    fig.suptitle("Headline score per task: mean over seeds, 95% bootstrap interval", fontsize=9)
    return save_figure(fig, path)


def plot_aggregates(iqm: Mapping[str, Interval], gap: Mapping[str, Interval],
                    rl: SimpleNamespace, labels: Mapping[str, str], path: Path) -> Path:
    """The IfO methods' IQM and optimality gap (best IQM on top) with their intervals."""
    order = sorted(iqm, key=lambda m: iqm[m][0])  # rliable draws the first at the bottom
    name = {m: labels.get(m, m) for m in order}
    # rliable's shapes: per method, (metrics,) points and (2: low and high, metrics) intervals
    points = {name[m]: np.array([iqm[m][0], gap[m][0]]) for m in order}
    intervals = {name[m]: np.array([[iqm[m][k], gap[m][k]] for k in (1, 2)]) for m in order}
    fig, axes = rl.plot_utils.plot_interval_estimates(
        points, intervals, metric_names=["IQM", "Optimality gap (lower is better)"],
        algorithms=[name[m] for m in order], xlabel="", subfigure_width=3.6,
        row_height=0.45)  # fmt: skip
    # rliable sizes the figure by its rows alone and its text for slides, and puts the x label
    # below the figure: room for the titles and the label, and the text sized, here
    fig.set_size_inches(fig.get_size_inches()[0], 0.45 * len(order) + 1.3)
    for ax in axes:
        ax.tick_params(labelsize=8)
        ax.title.set_fontsize(9)
    for text in list(fig.texts):
        text.remove()
    fig.supxlabel("headline score (0 random, 1 expert)", fontsize=8)
    fig.suptitle("IfO methods over the benchmark track's tasks (95% stratified bootstrap)",
                 fontsize=9)  # fmt: skip
    return save_figure(fig, path)
