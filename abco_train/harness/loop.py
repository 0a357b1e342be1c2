"""The harness: seeding, datasets, iterations, evaluation, checkpoints, resuming, plots.

It writes the run folder described in :mod:`abco_train.harness.run_folder`. Re-running a finished
run's command prints its stored result at once; re-running an interrupted one resumes after
its last checkpoint.

Evaluation episodes: mazes, every layout of the split (``eval_layouts`` limits that for
tests): the ``train`` split (for a run on procedural data, the first
:data:`abco_train.harness.training_data.TRAIN_EVAL_LAYOUTS` of its training layouts) while
training, and at the
end the ``train`` and ``test`` splits and, with :func:`abco_train.config.run.fresh_evaluation`,
:data:`FRESH_LAYOUTS` fresh layouts (``fresh_layouts(n, FRESH_LAYOUTS, FRESH_SEED)``, the
same for every run, in no dataset); classic control, ``eval_episodes`` episodes with seeds
``EVAL_SEED + 1000 * seed + i`` during training and ``FINAL_SEED + ...`` for the final
evaluation (episodes never seen while training).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

import abco_data
import abco_envs
from abco_train.config.run import RunConfig, fresh_evaluation
from abco_train.harness.rollouts import rollout, score
from abco_train.harness.run_folder import (
    CHECKPOINT,
    CONFIG,
    FINAL,
    METRICS,
    RunFolderError,
    finished_result,
    write_atomic,
)
from abco_train.harness.runtime import resolve_device, seed_everything
from abco_train.harness.training_data import TrainingData, load_training_data
from abco_train.methods.base import Method, TrainingFailed
from abco_train.methods.registry import get_method, identity, resolve_config

__all__ = ["train", "final_evaluation", "format_table", "load_checkpoint", "fresh_set",
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


def _eval_kwargs(cfg: RunConfig, data: TrainingData, split: str, seed: int,
                 layouts: np.ndarray | None = None) -> dict[str, Any]:  # fmt: skip
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


def _label_distribution(labels: np.ndarray | None, n_actions: int) -> list[float] | None:
    if labels is None or len(labels) == 0:
        return None
    return (np.bincount(labels, minlength=n_actions) / len(labels)).tolist()


def train(config: RunConfig, *, stop_after: int | None = None) -> dict[str, Any] | None:
    """Train ``config.method`` on ``config.env``, writing (or resuming) its run folder.

    Args:
        config: The run's settings (``None`` fields get their defaults).
        stop_after: Stop after this many iterations in total, before the final evaluation
            (as if interrupted; for tests of resuming). Not part of the config.

    Returns:
        The final evaluation (``final.json``), or ``None`` when stopped early.

    Raises:
        ConfigError: A bad setting, env or method.
        RunFolderError: The run folder holds a checkpoint of a different config.
    """
    from tqdm.auto import tqdm

    cfg = resolve_config(config)
    cfg = cfg.replace(device=resolve_device(cfg.device))
    run_dir = Path(cfg.run_dir)
    stored = finished_result(run_dir, asdict(cfg))
    if stored is not None:
        return stored
    run_dir.mkdir(parents=True, exist_ok=True)
    ckpt_path, metrics_path = run_dir / CHECKPOINT, run_dir / METRICS
    state = load_checkpoint(ckpt_path, cfg.device)
    if state is not None and identity(state["config"]) != identity(asdict(cfg)):
        raise RunFolderError(
            f"{run_dir} holds a run of another config; use another --run-dir or delete it"
        )
    write_atomic(run_dir / CONFIG, cfg.to_json())

    # -- seeding, data, method --------------------------------------------------------------
    rng = seed_everything(cfg.seed, cfg.threads, cfg.deterministic)
    data = load_training_data(cfg)
    method = get_method(cfg.method)(cfg, data, rng)
    history: list[dict[str, Any]] = []
    start = 0
    if state is not None:
        method.load_state_dict(state["method"])
        method.interactions.update(state.get("interactions", {}))
        torch.set_rng_state(state["torch_rng"].cpu())
        if state.get("cuda_rng") is not None and cfg.device.startswith("cuda"):
            torch.cuda.set_rng_state_all([x.cpu() for x in state["cuda_rng"]])
        start = int(state["iteration"]) + 1
        history = _read_history(metrics_path, start)
    write_atomic(metrics_path, "".join(json.dumps(r) + "\n" for r in history))

    # -- iterations -----------------------------------------------------------------------------
    total = method.num_iterations
    bar = tqdm(range(start, total), total=total, initial=start, desc=f"{cfg.method} {cfg.env}",
               disable=cfg.quiet, unit="iter")  # fmt: skip
    for i in bar:
        t0 = time.perf_counter()
        try:
            stats = method.train_iteration(i)
        except TrainingFailed as failure:  # never a normal-looking result
            bar.close()
            return _failed(cfg, run_dir, i, failure, history, dict(method.interactions))
        t_train = time.perf_counter() - t0
        episodes = _eval_kwargs(cfg, data, "train", EVAL_SEED)
        roll = rollout(method.act, cfg.env, protocol=cfg.protocol, record=not method.explores,
                       **episodes)  # fmt: skip
        evaluation = score(roll, data.reference)
        if method.explores:  # post-demonstrations of its own: the same episodes, explored
            roll = rollout(method.explore, cfg.env, protocol=cfg.protocol, record=True,
                           **episodes)  # fmt: skip
        post = method.observe(i, roll)
        record = {
            "iteration": i, "train": stats, "eval": evaluation, "post": post,
            "label_distribution": _label_distribution(method.expert_labels(), data.n_actions),
            "interactions": dict(method.interactions),
            "seconds_train": t_train, "seconds": time.perf_counter() - t0,
        }  # fmt: skip
        history.append(record)
        with metrics_path.open("a") as f:
            f.write(json.dumps(record) + "\n")
        payload = {"iteration": i, "method": method.state_dict(),
                   "interactions": dict(method.interactions),
                   "torch_rng": torch.get_rng_state(), "config": asdict(cfg),
                   "cuda_rng": torch.cuda.get_rng_state_all() if cfg.device.startswith("cuda")
                   else None}  # fmt: skip
        write_atomic(ckpt_path, lambda tmp, payload=payload: torch.save(payload, tmp))
        bar.set_postfix(P=f"{evaluation['performance']:.3f}",
                        win=f"{evaluation['success_rate']:.2f}")  # fmt: skip
        if stop_after is not None and i + 1 >= stop_after and i + 1 < total:
            bar.close()
            return None
    bar.close()

    final = final_evaluation(cfg, data, method, history, run_dir)
    write_atomic(run_dir / FINAL, json.dumps(final, indent=2))
    return final


def _failed(
    cfg: RunConfig, run_dir: Path, iteration: int, failure: TrainingFailed,
    history: list[dict[str, Any]], interactions: dict[str, int],
) -> dict[str, Any]:  # fmt: skip
    """Record a failed run: its last iteration's statistics, and a ``final.json`` with the
    failure's status and message and no evaluation (nothing to average by mistake)."""
    record = {"iteration": iteration, "train": failure.stats, "status": failure.status}
    with (run_dir / METRICS).open("a") as f:
        f.write(json.dumps(record) + "\n")
    final = {"env": cfg.env, "method": cfg.method, "seed": cfg.seed, "status": failure.status,
             "message": str(failure), "iteration": iteration, "interactions": interactions,
             "seconds": float(sum(h["seconds"] for h in history))}  # fmt: skip
    write_atomic(run_dir / FINAL, json.dumps(final, indent=2))
    return final

def load_checkpoint(path: Path, device: str) -> dict[str, Any] | None:
    """The checkpoint's state on ``device`` (a GPU run resumes on CPU), ``None`` without one.

    Raises:
        RunFolderError: The checkpoint is damaged (e.g. truncated).
    """
    if not path.exists():
        return None
    try:
        return torch.load(path, map_location=device, weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError) as exc:
        raise RunFolderError(f"{path} is damaged ({type(exc).__name__}: {exc}); delete it to "
                             "restart the run") from None  # fmt: skip


def _read_history(path: Path, start: int) -> list[dict[str, Any]]:
    """The metrics of iterations before ``start``; a damaged last line is dropped (the
    iteration it belonged to is re-run from its checkpoint only if the checkpoint is older)."""
    if not path.exists():
        return []
    history = []
    for line in path.read_text().splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by a kill; its iteration is in the checkpoint or redone
        if isinstance(record, dict) and record.get("iteration", start) < start:
            history.append(record)
    return history


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
    figures = {}
    for split, protocol in settings:
        is_fresh = split == "fresh"
        roll = rollout(method.act, cfg.env, protocol=protocol,
                       **_eval_kwargs(cfg, data, "train" if split == "episodes" else split,
                                      FINAL_SEED, fresh if is_fresh else None))  # fmt: skip
        key = split if not maze else f"{split}/{protocol}"
        results[key] = score(roll, fresh_ref if is_fresh else data.reference, per_episode=True)
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


def format_table(final: dict[str, Any]) -> str:
    """The final evaluation as a text table (a failed run: its status and message)."""
    if final.get("status", "ok") != "ok":
        return (f"{final['method']} on {final['env']} (seed {final['seed']}): FAILED "
                f"({final['status']}) at iteration {final.get('iteration')}: {final['message']}")
    rows = [(k, v) for k, v in final.items() if isinstance(v, dict) and "performance" in v]
    lines = [f"{final['method']} on {final['env']} (seed {final['seed']})",
             f"{'evaluation':<18}{'P':>8}{'AER':>10}{'success':>9}{'episodes':>10}"]
    for key, m in rows:
        lines.append(f"{key:<18}{m['performance']:>8.3f}{m['aer']:>10.3f}"
                     f"{m['success_rate']:>9.2f}{m['episodes']:>10d}")
    for name, path in final.get("figures", {}).items():
        lines.append(f"plot {name}: {path}")
    return "\n".join(lines)

