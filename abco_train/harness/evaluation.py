"""The evaluation of a run: which episodes, with which seeds, and the final evaluation.

Evaluation episodes: mazes, every layout of the split (``eval_layouts`` limits that for
tests): the ``train`` split (for a run on procedural data, the first
:data:`abco_train.harness.training_data.TRAIN_EVAL_LAYOUTS` of its training layouts) while
training, and at the end the ``train`` and ``test`` splits and, with
:func:`abco_train.config.run.fresh_evaluation`, :data:`FRESH_LAYOUTS` fresh layouts
(``fresh_layouts(n, FRESH_LAYOUTS, FRESH_SEED)``, the same for every run, in no dataset) or,
for a run that chooses settings (``held_out="validation"``), the ``train`` split and the
validation layouts of :func:`validation_set` instead of the test split and fresh layouts;
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
from abco_envs.maze.layout import layout_hash
from abco_envs.maze.pool import layout_pool
from abco_envs.maze.procedural import MIN_FRESH_SIZE
from abco_train.config.run import ConfigError, RunConfig, fresh_evaluation
from abco_train.harness.code_version import code_version
from abco_train.harness.rollouts import rollout, score
from abco_train.harness.score_reference import layout_cells, score_reference
from abco_train.harness.training_data import TrainingData
from abco_train.methods.base import Method

__all__ = ["episodes", "final_evaluation", "format_table", "fresh_set", "validation_set",
           "validation_layouts",
           "headline_block", "EVAL_SEED", "FINAL_SEED", "FRESH_LAYOUTS", "FRESH_SEED",
           "VALIDATION_SEED"]  # fmt: skip

EVAL_SEED = 100_000_000
FINAL_SEED = 200_000_000
#: Fresh layouts of the final evaluation: ``fresh_layouts(n, FRESH_LAYOUTS, FRESH_SEED)``, the
#: same for every run and method (a constant, not the run's seed).
FRESH_LAYOUTS = 100
FRESH_SEED = 300_000_000
#: The stream of a validation run's fresh layouts (:func:`validation_set`).
VALIDATION_SEED = 400_000_000


def fresh_set(cfg: RunConfig) -> tuple[np.ndarray, abco_data.ReferenceReturns]:
    """The fresh layouts of ``cfg``'s final evaluation and their references (mazes)."""
    n = abco_envs.maze_size(cfg.env)
    count = min(FRESH_LAYOUTS, cfg.eval_layouts or FRESH_LAYOUTS)
    return (abco_envs.fresh_layouts(n, count, FRESH_SEED),
            abco_data.fresh_reference(n, count, FRESH_SEED))  # fmt: skip


def validation_layouts(cfg: RunConfig, data: TrainingData) -> tuple[np.ndarray, str]:
    """The validation layouts of ``cfg``'s final evaluation and where they come from (mazes).

    A run whose test is the test split: the ``train`` split's layouts that none of its expert
    episodes plays (the test split is disjoint from the train split by construction). A run
    tested on fresh layouts, or one whose expert plays every train layout (5x5 and larger):
    :data:`FRESH_LAYOUTS` fresh layouts of a stream of their own (:data:`VALIDATION_SEED`), the
    test's fresh layouts left out.

    Raises:
        ConfigError: No such layout (a 3x3 run whose expert plays every train layout: a 3x3
            grid has a few dozen layouts beyond its pool).
    """
    n = abco_envs.maze_size(cfg.env)
    count = min(FRESH_LAYOUTS, cfg.eval_layouts or FRESH_LAYOUTS)
    kept: list[np.ndarray] = []
    source = "train split, in no expert episode"
    if not fresh_evaluation(cfg):
        pool = layout_pool(n)
        kept = [c for c, key in zip(pool.train, pool.train_ids)
                if key not in data.expert_layout_ids]  # fmt: skip
    if not kept and n > MIN_FRESH_SIZE:
        tested = {layout_hash(c) for c in abco_envs.fresh_layouts(n, FRESH_LAYOUTS, FRESH_SEED)}
        drawn = abco_envs.fresh_layouts(n, count + FRESH_LAYOUTS, VALIDATION_SEED)
        kept, source = [c for c in drawn if layout_hash(c) not in tested], "fresh"
    if not kept:
        raise ConfigError(f"--held-out validation: the expert episodes play every layout of the "
                          f"{n}x{n} train split, and a {n}x{n} maze has too few fresh layouts; "
                          f"give fewer --expert-episodes")  # fmt: skip
    return np.stack(kept[:count]), source


def validation_set(cfg: RunConfig, data: TrainingData
                   ) -> tuple[np.ndarray, abco_data.ReferenceReturns, str]:  # fmt: skip
    """:func:`validation_layouts`, with their references between them and the source."""
    layouts, source = validation_layouts(cfg, data)
    reference = abco_data.layout_reference(layouts, "validation", stream=1 + VALIDATION_SEED)
    return layouts, reference, source


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
    ``fresh/standard``), each under both protocols; a validation run (``held_out``) the
    ``train`` split and :func:`validation_set` (``validation/paper``, ...) instead; classic
    control: ``episodes``.
    """
    from abco_train.harness import plots

    maze = data.is_maze
    results: dict[str, Any] = {"env": cfg.env, "method": cfg.method, "seed": cfg.seed,
                               "status": "ok"}  # fmt: skip
    if cfg.layouts is not None:
        results["layouts"] = cfg.layouts
    splits, held = ["train", "test"], {}  # split -> (its layouts, their references)
    if maze and cfg.held_out == "validation":
        layouts, reference, source = validation_set(cfg, data)
        splits, held["validation"] = ["train", "validation"], (layouts, reference)
        results["validation_layouts"] = {"count": len(layouts), "source": source}
    elif maze and fresh_evaluation(cfg):
        splits.append("fresh")
        held["fresh"] = fresh_set(cfg)
        results["fresh_layouts"] = {"count": len(held["fresh"][0]), "seed": FRESH_SEED}
    settings = (
        [(s, p) for s in splits for p in ("paper", "standard")] if maze else
        [("episodes", "standard")]
    )  # fmt: skip
    results.update(_benchmark_keys(cfg, maze))
    figures = {}
    for split, protocol in settings:
        given, reference = held.get(split, (None, data.reference))
        roll = rollout(method.act, cfg.env, protocol=protocol,
                       **episodes(cfg, data, "train" if split == "episodes" else split,
                                      FINAL_SEED, given))  # fmt: skip
        key = split if not maze else f"{split}/{protocol}"
        cells = layout_cells(cfg, data, split, given) if maze else None
        results[key] = score(roll, reference, per_episode=True,
                             score_reference=score_reference(cfg, data, protocol, cells))
        if cfg.plots and maze and protocol == cfg.protocol and roll.paths is not None:
            k = min(cfg.plot_layouts, len(roll.paths))
            shown = given if given is not None else (
                data.train_layouts if split == "train" else None)
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

