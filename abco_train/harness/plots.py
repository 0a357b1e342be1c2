"""The run's figures (matplotlib, Agg backend): metrics, IDM label distribution, maze paths.

Also the figures' common ground, which ``abco report``'s plots (:mod:`abco_train.report.plots`)
share: :func:`pyplot` (matplotlib on Agg, imported on first use), :func:`action_names` and
:func:`save_figure`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from abco_train.harness.run_folder import write_atomic

__all__ = ["plot_metrics", "plot_label_distribution", "plot_maze_paths", "pyplot",
           "action_names", "save_figure"]  # fmt: skip

#: Names of the actions by number of actions (the mazes' moves); others are numbered.
ACTION_NAMES = {4: ["N", "S", "E", "W"]}


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (no display needed), imported on first use."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def action_names(n_actions: int) -> list[str]:
    """The names of ``n_actions`` actions: :data:`ACTION_NAMES`, else their numbers.

    Example:
        >>> action_names(4), action_names(3)
        (['N', 'S', 'E', 'W'], ['0', '1', '2'])
    """
    return ACTION_NAMES.get(n_actions, [str(a) for a in range(n_actions)])


def save_figure(fig: Any, path: Path) -> Path:
    """Lay out ``fig``, write it to ``path`` (PNG, 100 dpi) and close it.

    The PNG is written whole or not at all (:func:`abco_train.harness.run_folder.write_atomic`):
    a full disk or a read-only folder leaves the previous plot, never a cut or empty file.

    Raises:
        RunFolderError: ``path`` is not a new path or a regular file.
        OSError: It cannot be written.
    """
    try:
        fig.tight_layout()
        write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=100, format="png"))
    finally:
        pyplot().close(fig)
    return Path(path)


def plot_metrics(history: list[dict[str, Any]], path: Path) -> Path:
    """P, AER and success rate of the per-iteration evaluations, and the IDM's held-out
    accuracy (overall and per action) where the method has an IDM."""
    from matplotlib.ticker import MaxNLocator

    plt = pyplot()
    rows = [h for h in history if "eval" in h]
    its = [h["iteration"] for h in rows]
    idm = [h for h in history if "idm_val_accuracy" in h.get("train", {})]
    fig, axes = plt.subplots(1, 4 if idm else 3, figsize=(16 if idm else 12, 3.2))
    for ax, key, title in zip(axes, ("performance", "aer", "success_rate"),
                              ("Performance P", "AER", "Success rate")):  # fmt: skip
        values = [h["eval"][key] for h in rows]
        ax.plot(its, values, marker="o")
        ax.set_title(title)
        ax.set_xlabel("iteration")
        ax.grid(alpha=0.3)
        ax.set_ylim(*((0.0, 1.0) if key == "success_rate" else _visible_range(values)))
    if idm:
        ax, x = axes[3], [h["iteration"] for h in idm]
        ax.plot(x, [h["train"]["idm_val_accuracy"] for h in idm], marker="o", color="black",
                label="all")  # fmt: skip
        per_class = [h["train"].get("idm_val_class_accuracy") or [] for h in idm]
        n = max(map(len, per_class))
        names = action_names(n)
        for c in range(n):
            ax.plot(x, [pc[c] if c < len(pc) else np.nan for pc in per_class], marker=".",
                    alpha=0.7, label=names[c])  # fmt: skip
        ax.plot(x, [h["train"].get("idm_chance", np.nan) for h in idm], ls="--", color="grey",
                label="chance")  # fmt: skip
        ax.set_title("IDM held-out accuracy")
        ax.set_xlabel("iteration")
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=7, ncol=2)
        ax.grid(alpha=0.3)
    for ax in axes:  # iterations are whole numbers
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    return save_figure(fig, path)


def _visible_range(values: list[float]) -> tuple[float, float]:
    """Y limits that show a curve's changes at their size: at least 0.1 high (or a tenth of
    the values' magnitude), so rounding noise on a flat curve stays a flat line.

    Example:
        >>> _visible_range([0.9951, 0.9958])
        (0.94045, 1.05045)
    """
    finite = [v for v in values if np.isfinite(v)] or [0.0]
    low, high = min(finite), max(finite)
    span = max(high - low, 0.1, 0.1 * max(abs(low), abs(high)))
    middle = (low + high) / 2
    pad = span * 0.55
    return round(middle - pad, 6), round(middle + pad, 6)


def plot_label_distribution(
    history: list[dict[str, Any]], truth: np.ndarray, n_actions: int, path: Path
) -> Path:
    """The IDM's predicted action distribution on the expert data, per iteration, vs truth."""
    plt = pyplot()
    names = action_names(n_actions)
    rows = [h for h in history if h.get("label_distribution") is not None]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    width = 0.8 / (len(rows) + 1)
    x = np.arange(n_actions)
    true = np.bincount(truth, minlength=n_actions) / max(len(truth), 1)
    ax.bar(x, true, width, label="expert (true)", color="black")
    for k, h in enumerate(rows, start=1):
        ax.bar(x + k * width, h["label_distribution"], width, label=f"iter {h['iteration']}")
    ax.set_xticks(x + 0.4 - width / 2, names)
    ax.set_ylabel("share of expert transitions")
    ax.set_title("IDM labels of the expert data")
    ax.legend(fontsize=7, ncol=2)
    return save_figure(fig, path)


def plot_maze_paths(
    env_id: str, split: str, layout_indices: list[int], paths: list[np.ndarray],
    successes: list[bool], path: Path, layouts: np.ndarray | None = None,
) -> Path:  # fmt: skip
    """The agent's paths drawn over a few maze layouts: ``layout_indices`` of ``split``, or
    the ``layouts`` given (``(k, n, n)``, e.g. fresh ones; then the indices just count)."""
    import abco_envs
    from abco_envs.maze.render import MazeRenderer

    plt = pyplot()
    n = abco_envs.maze_size(env_id)
    pool = abco_envs.layout_pool(n).split(split) if layouts is None else np.asarray(layouts)
    renderer = MazeRenderer(n, 256, 256)
    fig, axes = plt.subplots(1, len(layout_indices), figsize=(3 * len(layout_indices), 3.2))
    axes = np.atleast_1d(axes)
    for ax, k, cells_path, ok in zip(axes, layout_indices, paths, successes):
        ax.imshow(renderer.background(pool[k]))
        centre = 256 / n
        ys = (cells_path[:, 0] + 0.5) * centre
        xs = (cells_path[:, 1] + 0.5) * centre
        ax.plot(xs, ys, color="tab:blue", lw=2)
        ax.scatter(xs[-1:], ys[-1:], color="tab:orange", zorder=3)
        ax.set_title(f"{split} #{k}: {'goal' if ok else 'failed'} ({len(cells_path) - 1} steps)",
                     fontsize=8)  # fmt: skip
        ax.axis("off")
    return save_figure(fig, path)
