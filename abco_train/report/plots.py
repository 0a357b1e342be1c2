"""The plots of ``abco report``: P per iteration, the IDM's label distribution, and
generalisation against the number of training layouts.

The first two read the runs of a grid by cell: ``by_cell[(env, method)]`` is a list of
:class:`abco_train.report.runs.Run` (anything with ``metrics()`` and ``row``); the third by
``(env, method, layouts)``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from abco_train.harness.plots import action_names, pyplot, save_figure

__all__ = ["plot_performance", "plot_label_distributions", "plot_generalisation",
           "GENERALISATION_PNG"]  # fmt: skip

GENERALISATION_PNG = "generalisation.png"

ByCell = Mapping[tuple[str, str], Sequence[Any]]


def _series(runs: Sequence[Any], pick: Callable[[dict[str, Any]], float | None]) -> np.ndarray:
    """``(seeds, iterations)`` of ``pick(record)`` (NaN where a run has fewer iterations)."""
    histories = [r.metrics() for r in runs]
    length = max((rec["iteration"] + 1 for h in histories for rec in h), default=0)
    out = np.full((len(runs), length), np.nan)
    for i, h in enumerate(histories):
        for rec in h:
            value = pick(rec)
            if value is not None:
                out[i, rec["iteration"]] = value
    return out


def plot_performance(by_cell: ByCell, path: Path, env_key: Callable[[str], Any] = str
                     ) -> Path | None:  # fmt: skip
    """P of the per-iteration evaluation, mean over seeds with the min-max band, per env."""
    envs = sorted({e for e, _ in by_cell}, key=env_key)
    if not envs:
        return None
    plt = pyplot()
    from matplotlib.ticker import MaxNLocator

    cols = min(3, len(envs))
    rows = -(-len(envs) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, env in zip(axes.flat, envs):
        for method in sorted(m for e, m in by_cell if e == env):
            p = _series(by_cell[(env, method)],
                        lambda rec: (rec.get("eval") or {}).get("performance"))  # fmt: skip
            if p.size == 0:
                continue
            its = np.arange(p.shape[1])
            with np.errstate(all="ignore"):
                mean, lo, hi = np.nanmean(p, 0), np.nanmin(p, 0), np.nanmax(p, 0)
            (line,) = ax.plot(its, mean, marker="o", ms=3, label=method)
            ax.fill_between(its, lo, hi, color=line.get_color(), alpha=0.2, lw=0)
        ax.set_title(env, fontsize=9)
        ax.set_xlabel("iteration")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("P")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(envs) :]:
        ax.axis("off")
    fig.suptitle("P per iteration: mean over seeds, band = min..max across seeds", fontsize=9)
    return save_figure(fig, path)


def _share(record: dict[str, Any], action: int, n_actions: int) -> float | None:
    dist = record.get("label_distribution")
    return dist[action] if dist and len(dist) == n_actions else None


def plot_label_distributions(by_cell: ByCell, env: str, methods: Sequence[str], path: Path
                             ) -> Path | None:  # fmt: skip
    """The IDM's predicted action shares on the expert data per iteration (mean over seeds)."""
    found = [m for m in methods if (env, m) in by_cell]
    if not found:
        return None
    plt = pyplot()
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, len(found), figsize=(5 * len(found), 3.4), squeeze=False)
    for ax, method in zip(axes[0], found):
        runs = by_cell[(env, method)]
        dists = [rec.get("label_distribution") for r in runs for rec in r.metrics()]
        n_actions = max((len(d) for d in dists if d), default=0)
        truth = next((r.row.get("reference", {}).get("expert_actions") for r in runs
                      if isinstance(r.row.get("reference"), dict)), None)  # fmt: skip
        names = action_names(n_actions)
        for a in range(n_actions):
            share = _series(runs, lambda rec, a=a, k=n_actions: _share(rec, a, k))
            with np.errstate(all="ignore"):
                (line,) = ax.plot(np.arange(share.shape[1]), np.nanmean(share, 0), marker="o",
                                  ms=3, label=names[a])  # fmt: skip
            if truth and len(truth) == n_actions:
                ax.axhline(truth[a], color=line.get_color(), ls="--", lw=1)
        ax.set_title(f"{method} on {env} (dashed: expert's true shares)", fontsize=9)
        ax.set_xlabel("iteration")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("share of IDM labels")
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_generalisation(cells: Mapping[tuple[str, str, int | None], Sequence[Any]], path: Path,
                        labels: Mapping[str, str] | None = None,
                        env_key: Callable[[str], Any] = str) -> Path | None:  # fmt: skip
    """Held-out success rate and P against the number of training layouts (log x).

    One row of two panels (success, P) per maze env with runs on procedural layouts; one
    line per method: the test split (solid) and fresh layouts (dashed, where evaluated),
    paper protocol, mean over seeds with the 95% bootstrap interval as error bars. Cells of
    the standard datasets (``layouts`` ``None``) are not drawn (they are not a point on the
    axis: 100 pool layouts with 10 expert paths each).
    """
    from abco_train.report.stats import cell_stats

    labels = labels or {}
    envs = sorted({e for e, _, k in cells if k is not None}, key=env_key)
    if not envs:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(len(envs), 2, figsize=(10, 3.4 * len(envs)), squeeze=False)
    palette = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    # one colour and one x range per method and K across all rows, so that rows compare
    every = list(dict.fromkeys(m for _, m, k in cells if k is not None))
    colour = {m: palette[i % len(palette)] for i, m in enumerate(every)}
    all_ks = [k for _, _, k in cells if k is not None]
    for row, env in zip(axes, envs):
        methods = [m for m in every if any(e == env and mm == m and k is not None
                                           for e, mm, k in cells)]
        for method in methods:
            ks = sorted(k for e, m, k in cells if e == env and m == method and k is not None)
            for split, style in (("test", "-"), ("fresh", "--")):
                for ax, metric in zip(row, ("success_rate", "performance")):
                    xs, ys, lo, hi = [], [], [], []
                    for k in ks:
                        runs = cells[(env, method, k)]
                        s = cell_stats([v for r in runs
                                        if (v := r.values(f"{split}/paper", metric)) is not None])
                        if s is None:
                            continue
                        xs.append(k)
                        ys.append(s.mean)
                        lo.append(s.mean - s.ci[0])
                        hi.append(s.ci[1] - s.mean)
                    if xs:
                        ax.errorbar(xs, ys, yerr=[lo, hi], ls=style, marker="o", ms=4,
                                    capsize=3, color=colour[method],
                                    label=f"{labels.get(method, method)}, {split}")
        for ax, title in zip(row, ("held-out success rate", "held-out P")):
            ax.set_xscale("log")
            ax.set_xlim(min(all_ks) / 1.6, max(all_ks) * 1.6)
            ax.set_xlabel("training layouts K (first K procedural layouts)")
            ax.set_title(f"{env}: {title} (paper protocol)", fontsize=9)
            ax.grid(alpha=0.3, which="both")
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7)
        row[0].set_ylim(-0.02, 1.02)
    fig.suptitle("Generalisation: test split (solid) and fresh layouts (dashed); mean over "
                 "seeds, bars = 95% bootstrap CI", fontsize=9)
    return save_figure(fig, path)
