"""The harness's loop: a run's iterations, written to (and resumed from) its run folder.

It writes the run folder described in :mod:`abco_train.harness.run_folder`. Re-running a
finished run's command prints its stored result at once; re-running an interrupted one
resumes after its last checkpoint (:mod:`abco_train.harness.checkpoint`). Which episodes
evaluate a run, and its final evaluation: :mod:`abco_train.harness.evaluation`.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from abco_train.config.run import RunConfig
from abco_train.harness.checkpoint import load_checkpoint, restore, save_checkpoint
from abco_train.harness.evaluation import EVAL_SEED, episodes, final_evaluation
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

__all__ = ["train"]


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
    run_dir = Path(cfg.run_dir or ".")
    stored = finished_result(run_dir, asdict(cfg))
    if stored is not None:
        return stored
    state = _open_run_folder(run_dir, cfg)

    # -- seeding, data, method --------------------------------------------------------------
    rng = seed_everything(cfg.seed, cfg.threads, cfg.deterministic)
    data = load_training_data(cfg)
    method = get_method(cfg.method)(cfg, data, rng)
    start = 0 if state is None else restore(method, state, cfg)
    history = _read_history(run_dir / METRICS, start) if start else []
    write_atomic(run_dir / METRICS, "".join(json.dumps(r) + "\n" for r in history))

    # -- iterations -------------------------------------------------------------------------
    total = method.num_iterations
    bar = tqdm(range(start, total), total=total, initial=start, desc=f"{cfg.method} {cfg.env}",
               disable=cfg.quiet, unit="iter")  # fmt: skip
    for i in bar:
        try:
            record = _iteration(method, cfg, data, i)
        except TrainingFailed as failure:  # never a normal-looking result
            bar.close()
            return _failed(cfg, run_dir, i, failure, history, dict(method.interactions))
        history.append(record)
        with (run_dir / METRICS).open("a") as f:
            f.write(json.dumps(record) + "\n")
        save_checkpoint(run_dir / CHECKPOINT, i, method, cfg)
        bar.set_postfix(P=f"{record['eval']['performance']:.3f}",
                        win=f"{record['eval']['success_rate']:.2f}")  # fmt: skip
        if stop_after is not None and i + 1 >= stop_after and i + 1 < total:
            bar.close()
            return None
    bar.close()

    final = final_evaluation(cfg, data, method, history, run_dir)
    write_atomic(run_dir / FINAL, json.dumps(final, indent=2))
    return final


def _open_run_folder(run_dir: Path, cfg: RunConfig) -> dict[str, Any] | None:
    """Create the folder, check a checkpoint there is of this config, write ``config.json``;
    the checkpoint's state, if any.

    Raises:
        RunFolderError: The folder holds a run of another config.
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    state = load_checkpoint(run_dir / CHECKPOINT, cfg.device)
    if state is not None and identity(state["config"]) != identity(asdict(cfg)):
        raise RunFolderError(
            f"{run_dir} holds a run of another config; use another --run-dir or delete it"
        )
    write_atomic(run_dir / CONFIG, cfg.to_json())
    return state


def _iteration(method: Method, cfg: RunConfig, data: TrainingData, i: int) -> dict[str, Any]:
    """Iteration ``i``: train, evaluate on the training episodes, hand the post-demonstrations
    to the method; its metrics record.

    Raises:
        TrainingFailed: The method's health check failed.
    """
    t0 = time.perf_counter()
    stats = method.train_iteration(i)
    t_train = time.perf_counter() - t0
    kwargs = episodes(cfg, data, "train", EVAL_SEED)
    roll = rollout(method.act, cfg.env, protocol=cfg.protocol, record=not method.explores,
                   **kwargs)  # fmt: skip
    evaluation = score(roll, data.reference)
    if method.explores:  # post-demonstrations of its own: the same episodes, explored
        roll = rollout(method.explore, cfg.env, protocol=cfg.protocol, record=True, **kwargs)
    post = method.observe(i, roll)
    return {
        "iteration": i, "train": stats, "eval": evaluation, "post": post,
        "label_distribution": _label_distribution(method.expert_labels(), data.n_actions),
        "interactions": dict(method.interactions),
        "seconds_train": t_train, "seconds": time.perf_counter() - t0,
    }  # fmt: skip


def _label_distribution(labels: np.ndarray | None, n_actions: int) -> list[float] | None:
    if labels is None or len(labels) == 0:
        return None
    return (np.bincount(labels, minlength=n_actions) / len(labels)).tolist()


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
