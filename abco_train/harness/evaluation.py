"""The evaluation of a run: which episodes, with which seeds, and the final evaluation.

Evaluation episodes: mazes, every layout of the split (``eval_layouts`` limits that for
tests): the ``train`` split (for a run on procedural data, the first
:data:`abco_train.harness.training_data.TRAIN_EVAL_LAYOUTS` of its training layouts) while
training, and at the end the ``train`` and ``test`` splits and, with
:func:`abco_train.config.run.fresh_evaluation`, :data:`FRESH_LAYOUTS` fresh layouts
(``fresh_layouts(n, FRESH_LAYOUTS, FRESH_SEED)``, the same for every run, in no dataset);
classic control, ``eval_episodes`` episodes with seeds ``EVAL_SEED + 1000 * seed + i`` during
training and ``FINAL_SEED + ...`` for the final evaluation (episodes never seen while
training).
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

import abco_data
import abco_envs
from abco_train.config.run import RunConfig, fresh_evaluation
from abco_train.harness.code_version import code_version
from abco_train.harness.rollouts import rollout, score
from abco_train.harness.score_reference import layout_cells, score_reference
from abco_train.harness.training_data import TrainingData
from abco_train.methods.base import Method

__all__ = ["episodes", "final_evaluation", "format_table", "fresh_set", "headline_block",
           "EVAL_SEED", "FINAL_SEED", "FRESH_LAYOUTS", "FRESH_SEED"]  # fmt: skip

EVAL_SEED = 100_000_000
FINAL_SEED = 200_000_000
#: Fresh layouts of the final evaluation: ``fresh_layouts(n, FRESH_LAYOUTS, FRESH_SEED)``, the
#: same for every run and method (a constant, not the run's seed).
FRESH_LAYOUTS = 100
FRESH_SEED = 300_000_000


def fresh_set(cfg: RunConfig) -> tuple[np.ndarray, abco_data.ReferenceReturns]:
    """The fresh layouts of ``cfg``'s final evaluation and their references (mazes)."""
    n = abco_envs.maze_size(cfg.env)
    count = min(FRESH_LAYOUTS, cfg.eval_layouts or FRESH_LAYOUTS)
    return (abco_envs.fresh_layouts(n, count, FRESH_SEED),
            abco_data.fresh_reference(n, count, FRESH_SEED))  # fmt: skip


def episodes(cfg: RunConfig, data: TrainingData, split: str, seed: int,
             layouts: np.ndarray | None = None) -> dict[str, Any]:  # fmt: skip
    """The :func:`~abco_train.harness.rollouts.rollout` arguments of an evaluation of ``split``
    with base seed ``seed`` (:data:`EVAL_SEED` while training, :data:`FINAL_SEED` at the end)."""
    if split == "train" and layouts is None:
        layouts = data.train_layouts  # a run on procedural data: its training layouts
    return {
        "episodes": cfg.eval_layouts if data.is_maze else cfg.eval_episodes,
        "split": split,
        "env_kwargs": data.env_kwargs,
        "seed": seed + 1000 * cfg.seed,
        "max_steps": cfg.eval_max_steps,
        **({"layouts": layouts} if layouts is not None else {}),
    }


def final_evaluation(
    cfg: RunConfig, data: TrainingData, method: Method, history: list[dict[str, Any]],
    run_dir: Path,
) -> dict[str, Any]:
    """Evaluate the final policy and draw the plots.

    Mazes: the ``train`` and ``test`` splits (keys ``train/paper``, ``train/standard``, ...),
    and with :func:`~abco_train.config.run.fresh_evaluation` the fresh layouts (``fresh/paper``,
    ``fresh/standard``), each under both protocols; classic control: ``episodes``.
    """
    from abco_train.harness import plots

    maze = data.is_maze
    results: dict[str, Any] = {"env": cfg.env, "method": cfg.method, "seed": cfg.seed,
                               "status": "ok"}  # fmt: skip
    if cfg.layouts is not None:
        results["layouts"] = cfg.layouts
    splits = ["train", "test"]
    fresh, fresh_ref = None, None
    if maze and fresh_evaluation(cfg):
        splits.append("fresh")
        fresh, fresh_ref = fresh_set(cfg)
        results["fresh_layouts"] = {"count": len(fresh), "seed": FRESH_SEED}
    settings = (
        [(s, p) for s in splits for p in ("paper", "standard")] if maze else
        [("episodes", "standard")]
    )  # fmt: skip
    results.update(_benchmark_keys(cfg, maze))
    figures = {}
    for split, protocol in settings:
        is_fresh = split == "fresh"
        roll = rollout(method.act, cfg.env, protocol=protocol,
                       **episodes(cfg, data, "train" if split == "episodes" else split,
                                      FINAL_SEED, fresh if is_fresh else None))  # fmt: skip
        key = split if not maze else f"{split}/{protocol}"
        cells = layout_cells(cfg, data, split, fresh if is_fresh else None) if maze else None
        results[key] = score(roll, fresh_ref if is_fresh else data.reference, per_episode=True,
                             score_reference=score_reference(cfg, data, protocol, cells))
        if cfg.plots and maze and protocol == cfg.protocol and roll.paths is not None:
            k = min(cfg.plot_layouts, len(roll.paths))
            shown = (fresh if is_fresh else data.train_layouts if split == "train" else None)
            if k:
                figures[f"paths_{split}"] = str(plots.plot_maze_paths(
                    cfg.env, split, list(range(k)), roll.paths[:k],
                    [bool(x) for x in roll.successes[:k]], run_dir / f"paths_{split}.png",
                    layouts=None if shown is None else shown[:k],
                ))  # fmt: skip
    if history and cfg.plots:
        figures["metrics"] = str(plots.plot_metrics(history, run_dir / "metrics.png"))
        figures["labels"] = str(plots.plot_label_distribution(
            history, data.expert_eval_actions, data.n_actions, run_dir / "labels.png"))
    results["figures"] = figures
    results["interactions"] = dict(method.interactions)
    results["seconds"] = float(sum(h["seconds"] for h in history))
    return results


def headline_block(cfg: RunConfig, maze: bool) -> str:
    """The block a run is ranked by: ``cfg.headline``, else ``train/{protocol}`` (mazes: the
    paper's setting, the layouts trained on) or ``episodes``."""
    if cfg.headline is not None:
        return cfg.headline
    return f"train/{cfg.protocol}" if maze else "episodes"


def _benchmark_keys(cfg: RunConfig, maze: bool) -> dict[str, Any]:
    """``task``, ``budget``, ``headline`` and ``code_version`` of the final record."""
    return {"task": cfg.task, "budget": cfg.budget, "headline": headline_block(cfg, maze),
            "code_version": code_version()}  # fmt: skip


def format_table(final: dict[str, Any]) -> str:
    """The final evaluation as a text table (a failed run: its status and message)."""
    run = f"{final.get('method')} on {final.get('env')} (seed {final.get('seed')})"
    if final.get("status", "ok") != "ok":
        return (f"{run}: FAILED ({final['status']}) at iteration {final.get('iteration')}: "
                f"{final.get('message')}")  # fmt: skip
    rows = [(k, v) for k, v in final.items() if isinstance(v, dict) and "performance" in v]
    lines = [run,
             f"{'evaluation':<18}{'score':>8}{'P':>8}{'AER':>10}{'success':>9}{'episodes':>10}"]
    for key, m in rows:
        shown = f"{m['score']:>8.3f}" if m.get("score") is not None else f"{'-':>8}"
        mark = " *" if key == final.get("headline") else ""
        lines.append(f"{key:<18}{shown}{m['performance']:>8.3f}{m['aer']:>10.3f}"
                     f"{m['success_rate']:>9.2f}{m['episodes']:>10d}{mark}")
    lines += [wrapped for line in _legend(final, [key for key, _ in rows])
              for wrapped in textwrap.wrap(line, 96, subsequent_indent="  ")]
    for name, path in final.get("figures", {}).items():
        lines.append(f"plot {name}: {path}")
    return "\n".join(lines)


def _legend(final: dict[str, Any], keys: list[str]) -> list[str]:
    """What the table's columns and mark mean, in a few lines under it."""
    headline = final.get("headline")
    lines = ["score: 0 = a uniform random policy, 1 = the expert, both measured the same way "
             "(protocol, layouts); P: the ABCO paper's performance measure; AER: mean episode "
             "return."]  # fmt: skip
    if headline in keys:
        lines.append(f"* {headline}: the block this run is ranked by.")
    negative = [k for k in keys if k.endswith("/standard")
                and (final[k].get("score") or 0.0) < 0]  # fmt: skip
    if negative:
        lines.append("standard: the env's own rules, up to 1,000 steps an episode; a policy "
                     "that loops where a random walk would stumble on the goal scores below "
                     "0 there (paper: the 4th visit of a cell ends the episode).")
    return lines

