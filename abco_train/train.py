"""The harness: datasets, iterations, evaluation, run folder, checkpoints, resuming, plots.

A run folder holds::

    config.json        the resolved config
    metrics.jsonl      one line per iteration: training stats, evaluation, I_s composition,
                       the IDM's label distribution on the expert data, seconds
    checkpoint.pt      the latest iteration's full state (method, rngs); re-running the same
                       command resumes after it
    final.json         the final evaluation (mazes: train and test splits, both protocols)
    metrics.png, labels.png, paths_{split}.png   the plots

Evaluation episodes: mazes, every layout of the split (``eval_layouts`` limits that for
tests); classic control, ``eval_episodes`` episodes with seeds ``EVAL_SEED + 1000 * seed + i``
during training and ``FINAL_SEED + ...`` for the final evaluation (episodes never seen while
training).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from abco_train.abco import Config, load_training_data, seed_everything
from abco_train.evaluate import rollout, score
from abco_train.methods import get_method

__all__ = ["train", "final_evaluation", "format_table", "EVAL_SEED", "FINAL_SEED"]

EVAL_SEED = 100_000_000
FINAL_SEED = 200_000_000
#: Settings that may change between a run and its resumption.
_RUNTIME_KEYS = ("quiet", "run_dir", "cache_dir", "threads", "expert_data", "pre_data", "plots",
                 "plot_layouts")


def _comparable(cfg: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in cfg.items() if k not in _RUNTIME_KEYS}


def _eval_kwargs(cfg: Config, data: Any, split: str, seed: int) -> dict[str, Any]:
    maze = data.reference.layout_ids is not None
    return {
        "episodes": cfg.eval_layouts if maze else cfg.eval_episodes,
        "split": split,
        "env_kwargs": data.env_kwargs,
        "seed": seed + 1000 * cfg.seed,
        "max_steps": cfg.eval_max_steps,
    }


def _save_checkpoint(path: Path, payload: dict[str, Any]) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)


def _label_distribution(labels: np.ndarray | None, n_actions: int) -> list[float] | None:
    if labels is None or len(labels) == 0:
        return None
    return (np.bincount(labels, minlength=n_actions) / len(labels)).tolist()


def train(config: Config, *, stop_after: int | None = None) -> dict[str, Any] | None:
    """Train ``config.method`` on ``config.env``, writing (or resuming) its run folder.

    Args:
        config: The run's settings (``None`` fields get their defaults).
        stop_after: Stop after this many iterations in total, before the final evaluation
            (as if interrupted; for tests of resuming). Not part of the config.

    Returns:
        The final evaluation (``final.json``), or ``None`` when stopped early.

    Raises:
        ValueError: The run folder holds a checkpoint of a different config.
    """
    from tqdm.auto import tqdm

    cfg = config.resolved()
    run_dir = Path(cfg.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    ckpt_path, metrics_path = run_dir / "checkpoint.pt", run_dir / "metrics.jsonl"
    state = torch.load(ckpt_path, weights_only=False) if ckpt_path.exists() else None
    if state is not None and _comparable(state["config"]) != _comparable(asdict(cfg)):
        raise ValueError(
            f"{run_dir} holds a run of another config; use another --run-dir or delete it"
        )
    (run_dir / "config.json").write_text(cfg.to_json())

    # -- seeding, data, method --------------------------------------------------------------
    rng = seed_everything(cfg.seed, cfg.threads, cfg.deterministic)
    data = load_training_data(cfg)
    method = get_method(cfg.method)(cfg, data, rng)
    history: list[dict[str, Any]] = []
    start = 0
    if state is not None:
        method.load_state_dict(state["method"])
        torch.set_rng_state(state["torch_rng"])
        start = int(state["iteration"]) + 1
        if metrics_path.exists():
            lines = metrics_path.read_text().splitlines()
            history = [r for r in map(json.loads, lines) if r["iteration"] < start]
    metrics_path.write_text("".join(json.dumps(r) + "\n" for r in history))

    # -- iterations -----------------------------------------------------------------------------
    total = method.num_iterations
    bar = tqdm(range(start, total), total=total, initial=start, desc=f"{cfg.method} {cfg.env}",
               disable=cfg.quiet, unit="iter")  # fmt: skip
    for i in bar:
        t0 = time.perf_counter()
        stats = method.train_iteration(i)
        t_train = time.perf_counter() - t0
        roll = rollout(method.act, cfg.env, protocol=cfg.protocol, record=True,
                       **_eval_kwargs(cfg, data, "train", EVAL_SEED))  # fmt: skip
        evaluation = score(roll, data.reference)
        post = method.observe(i, roll)
        record = {
            "iteration": i, "train": stats, "eval": evaluation, "post": post,
            "label_distribution": _label_distribution(method.expert_labels(), data.n_actions),
            "seconds_train": t_train, "seconds": time.perf_counter() - t0,
        }  # fmt: skip
        history.append(record)
        with metrics_path.open("a") as f:
            f.write(json.dumps(record) + "\n")
        _save_checkpoint(ckpt_path, {
            "iteration": i, "method": method.state_dict(), "torch_rng": torch.get_rng_state(),
            "config": asdict(cfg),
        })  # fmt: skip
        bar.set_postfix(P=f"{evaluation['performance']:.3f}",
                        win=f"{evaluation['success_rate']:.2f}")  # fmt: skip
        if stop_after is not None and i + 1 >= stop_after and i + 1 < total:
            bar.close()
            return None
    bar.close()

    final = final_evaluation(cfg, data, method, history, run_dir)
    (run_dir / "final.json").write_text(json.dumps(final, indent=2))
    return final


def final_evaluation(
    cfg: Config, data: Any, method: Any, history: list[dict[str, Any]], run_dir: Path
) -> dict[str, Any]:
    """Evaluate the final policy (mazes: both splits and protocols) and draw the plots."""
    from abco_train import plots

    maze = data.reference.layout_ids is not None
    results: dict[str, Any] = {"env": cfg.env, "method": cfg.method, "seed": cfg.seed}
    settings = (
        [(s, p) for s in ("train", "test") for p in ("paper", "standard")] if maze else
        [("episodes", "standard")]
    )  # fmt: skip
    figures = {}
    for split, protocol in settings:
        roll = rollout(method.act, cfg.env, protocol=protocol,
                       **_eval_kwargs(cfg, data, "train" if split == "episodes" else split,
                                      FINAL_SEED))  # fmt: skip
        key = split if not maze else f"{split}/{protocol}"
        results[key] = score(roll, data.reference, per_episode=True)
        if cfg.plots and maze and protocol == cfg.protocol and roll.paths is not None:
            k = min(cfg.plot_layouts, len(roll.paths))
            if k:
                figures[f"paths_{split}"] = str(plots.plot_maze_paths(
                    cfg.env, split, list(range(k)), roll.paths[:k],
                    [bool(x) for x in roll.successes[:k]], run_dir / f"paths_{split}.png",
                ))  # fmt: skip
    if history and cfg.plots:
        figures["metrics"] = str(plots.plot_metrics(history, run_dir / "metrics.png"))
        figures["labels"] = str(plots.plot_label_distribution(
            history, data.expert_eval_actions, data.n_actions, run_dir / "labels.png"))
    results["figures"] = figures
    results["seconds"] = float(sum(h["seconds"] for h in history))
    return results


def format_table(final: dict[str, Any]) -> str:
    """The final evaluation as a text table."""
    rows = [(k, v) for k, v in final.items() if isinstance(v, dict) and "performance" in v]
    lines = [f"{final['method']} on {final['env']} (seed {final['seed']})",
             f"{'evaluation':<18}{'P':>8}{'AER':>10}{'success':>9}{'episodes':>10}"]
    for key, m in rows:
        lines.append(f"{key:<18}{m['performance']:>8.3f}{m['aer']:>10.3f}"
                     f"{m['success_rate']:>9.2f}{m['episodes']:>10d}")
    for name, path in final.get("figures", {}).items():
        lines.append(f"plot {name}: {path}")
    return "\n".join(lines)


def config_with(config: Config, **changes: Any) -> Config:
    """``config`` with some fields replaced (a convenience for scripts)."""
    return replace(config, **changes)
