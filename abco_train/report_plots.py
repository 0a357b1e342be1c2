"""The plots of ``abco report``: P per iteration, and the IDM's label distribution.

Both read the runs of a grid by cell: ``by_cell[(env, method)]`` is a list of
:class:`abco_train.report.Run` (anything with ``metrics()`` and ``row``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["pyplot", "plot_performance", "plot_label_distributions"]

ByCell = Mapping[tuple[str, str], Sequence[Any]]


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _series(runs: Sequence[Any], pick: Callable[[dict[str, Any]], float | None]) -> np.ndarray:
    """``(seeds, iterations)`` of ``pick(record)`` (NaN where a run has fewer iterations)."""
    histories = [r.metrics() for r in runs]
    length = max((len(h) for h in histories), default=0)
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
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _share(record: dict[str, Any], action: int, n_actions: int) -> float | None:
    dist = record.get("label_distribution")
    return dist[action] if dist and len(dist) == n_actions else None


def plot_label_distributions(by_cell: ByCell, env: str, methods: Sequence[str], path: Path
                             ) -> Path | None:  # fmt: skip
    """The IDM's predicted action shares on the expert data per iteration (mean over seeds)."""
    from abco_train.plots import ACTION_NAMES

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
        names = ACTION_NAMES.get(n_actions, [str(a) for a in range(n_actions)])
        for a in range(n_actions):
            share = _series(runs, lambda rec, a=a, k=n_actions: _share(rec, a, k))
            with np.errstate(all="ignore"):
                (line,) = ax.plot(np.arange(share.shape[1]), np.nanmean(share, 0), marker="o",
                                  ms=3, label=names[a])  # fmt: skip
            if truth:
                ax.axhline(truth[a], color=line.get_color(), ls="--", lw=1)
        ax.set_title(f"{method} on {env} (dashed: expert's true shares)", fontsize=9)
        ax.set_xlabel("iteration")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("share of IDM labels")
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
