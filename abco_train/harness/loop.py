"""The harness's loop: a run's iterations, written to (and resumed from) its run folder.

It writes the run folder described in :mod:`abco_train.harness.run_folder`. Re-running a
finished run's command prints its stored result at once; re-running an interrupted one
resumes after its last checkpoint (:mod:`abco_train.harness.checkpoint`). Which episodes
evaluate a run, and its final evaluation: :mod:`abco_train.harness.evaluation`.

A run holds its folder's lock (:func:`abco_train.harness.run_lock.run_folder_lock`) from
start to end: a second writer of the folder is refused at once. Every file is written whole
or not at all: a full disk or a read-only folder ends the run with an ``OSError`` naming the
file, the previous checkpoint, metrics and plots intact.

A run with a ``--budget`` spends at most that many environment interactions
(:meth:`~abco_train.methods.base.Method.count`): the rollouts a method learns from are cut at
its :attr:`~abco_train.methods.base.Method.budget_left` steps (the evaluation itself is never
cut), and training stops, to the final evaluation, after the iteration that had nothing left
to spend (``"stopped": "budget"`` in its metrics and in ``final.json``). A method that counts
past its budget anyway ends the run with status ``over_budget``.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

import abco_envs
from abco_train.config.envs import use_success_rule
from abco_train.config.run import RunConfig
from abco_train.harness.checkpoint import load_checkpoint, restore, save_checkpoint
from abco_train.harness.code_version import code_version
from abco_train.harness.evaluation import (
    EVAL_SEED,
    episodes,
    final_evaluation,
    validation_layouts,
)
from abco_train.harness.metrics import health_summary
from abco_train.harness.rollouts import Rollouts, rollout, score
from abco_train.harness.run_folder import (
    CHECKPOINT,
    CONFIG,
    FINAL,
    MAX_JSON_BYTES,
    METRICS,
    RunFolderError,
    check_run_dir,
    config_differences,
    finished_result,
    read_capped,
    write_atomic,
)
from abco_train.harness.run_lock import HOLDER_FILE, LOCK_FILE, run_folder_lock
from abco_train.harness.runtime import resolve_device, seed_everything
from abco_train.harness.training_data import (
    TrainingData,
    check_dataset_paths,
    load_training_data,
)
from abco_train.methods.base import INTERACTION_KINDS, BudgetExceeded, Method, TrainingFailed
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
        MissingDependencyError: The env needs a package that is not installed (LunarLander:
            Box2D); the message names the abco extra to install.
        RunFolderError: The run folder is no folder, holds a checkpoint of a different config
            or damaged files, or is in use by another process
            (:class:`~abco_train.harness.run_lock.RunFolderInUseError`).
        OSError: A file of the run folder cannot be written (a full disk, a read-only
            folder); what was written before stays as it was.
    """
    cfg = resolve_config(config)
    cfg = cfg.replace(device=resolve_device(cfg.device, cfg.arch))
    run_dir = Path(cfg.run_dir or ".")
    check_run_dir(run_dir)
    stored = finished_result(run_dir, asdict(cfg))  # read only: a read-only folder answers
    if stored is not None:
        return stored
    abco_envs.check_env_dependencies(cfg.env)  # LunarLander without Box2D: the extra, in a line
    use_success_rule(cfg.env, cfg.success)  # --success, or terminated for an env of the user's
    check_dataset_paths(cfg)  # "no such file", before the folder is touched
    new_folder = not os.path.lexists(run_dir)
    try:
        with run_folder_lock(run_dir, "abco train"):
            return _train(cfg, run_dir, stop_after)
    except BaseException:
        if new_folder:  # refused (or stopped) before its first iteration: leave no folder
            _remove_unstarted(run_dir)
        raise


def _remove_unstarted(run_dir: Path) -> None:
    """Delete a folder this run created if it holds nothing but its config and lock files."""
    with contextlib.suppress(OSError):
        names = {p.name for p in run_dir.iterdir()}
        if names <= {CONFIG, LOCK_FILE, HOLDER_FILE}:
            for name in names:
                (run_dir / name).unlink()
            run_dir.rmdir()


def _train(cfg: RunConfig, run_dir: Path, stop_after: int | None) -> dict[str, Any] | None:
    """:func:`train` in its locked run folder."""
    from abco_data.progress import progress_bar

    stored = finished_result(run_dir, asdict(cfg))  # finished by another process meanwhile?
    if stored is not None:
        return stored
    state = _open_run_folder(run_dir, cfg)

    # -- seeding, data, method --------------------------------------------------------------
    rng = seed_everything(cfg.seed, cfg.threads, cfg.deterministic)
    data = load_training_data(cfg)
    if data.is_maze and cfg.held_out == "validation":
        validation_layouts(cfg, data)  # refuse a run without them before it trains
    try:
        method = get_method(cfg.method)(cfg, data, rng)
    except BudgetExceeded as exc:  # a method that counts past the budget as it starts
        return _failed(cfg, run_dir, 0, _over_budget(exc), [],
                       dict.fromkeys(INTERACTION_KINDS, 0))  # fmt: skip
    start = 0 if state is None else restore(method, state, cfg, run_dir / CHECKPOINT)
    history = _read_history(run_dir / METRICS, start, data.n_actions) if start else []
    if history:
        _write_history(run_dir, history)  # without the iterations the checkpoint has not
    elif (run_dir / METRICS).exists():
        (run_dir / METRICS).unlink()  # a restart; the first iteration writes it anew

    # -- iterations -------------------------------------------------------------------------
    total = method.num_iterations
    end = start if _stop(history) else total  # a resumed run that had stopped for its budget
    bar = progress_bar(range(start, end), total=total, initial=start,
                       desc=f"{cfg.method} {cfg.env}", disable=cfg.quiet, unit="iter")
    for i in bar:
        try:
            record = _iteration(method, cfg, data, i)
        except (TrainingFailed, BudgetExceeded) as failure:  # never a normal-looking result
            bar.close()
            if isinstance(failure, BudgetExceeded):
                failure = _over_budget(failure)
            return _failed(cfg, run_dir, i, failure, history, dict(method.interactions))
        history.append(record)
        _write_history(run_dir, history)
        save_checkpoint(run_dir / CHECKPOINT, i, method, cfg)
        bar.set_postfix(P=f"{record['eval']['performance']:.3f}",
                        win=f"{record['eval']['success_rate']:.2f}")  # fmt: skip
        if "stopped" in record:
            break
        if stop_after is not None and i + 1 >= stop_after and i + 1 < total:
            bar.close()
            return None
    bar.close()

    final = final_evaluation(cfg, data, method, history, run_dir)
    final.update(_stop(history))
    final["health"] = health_summary(history)  # what the checks flagged; they never stop a run
    write_atomic(run_dir / FINAL, json.dumps(final, indent=2))
    return final


def _stop(history: list[dict[str, Any]]) -> dict[str, Any]:
    """Why and after which iteration training stopped early (``final.json``'s ``stopped``,
    ``stopped_after``), from the last iteration's record; empty when it ran to the end."""
    if not history or "stopped" not in history[-1]:
        return {}
    return {"stopped": history[-1]["stopped"], "stopped_after": history[-1]["iteration"]}


def _over_budget(exc: BudgetExceeded) -> TrainingFailed:
    """The failure (status ``over_budget``) that ends a run whose method counted past its
    ``--budget``."""
    return TrainingFailed("over_budget", str(exc))


def _open_run_folder(run_dir: Path, cfg: RunConfig) -> dict[str, Any] | None:
    """Create the folder, check a checkpoint there is of this config, write ``config.json``;
    the checkpoint's state, if any.

    Raises:
        RunFolderError: The folder holds a run of another config (a checkpoint, or a
            ``final.json``: never replaced), or a damaged checkpoint.
    """
    if (run_dir / FINAL).exists() and config_differences(run_dir, asdict(cfg)):
        raise RunFolderError(f"{run_dir} holds a run of another config (finished); use "
                             "another --run-dir or delete it")  # fmt: skip
    state = load_checkpoint(run_dir / CHECKPOINT)
    if state is not None and config_differences(run_dir, asdict(cfg)):  # damaged: one line
        raise RunFolderError(f"{run_dir}/{CONFIG} is not the config of its checkpoint's run; "
                             "use another --run-dir or delete the folder")  # fmt: skip
    if state is not None and identity(state["config"]) != identity(asdict(cfg)):
        raise RunFolderError(
            f"{run_dir} holds a run of another config; use another --run-dir or delete it"
        )
    write_atomic(run_dir / CONFIG, cfg.to_json())
    return state


def _iteration(method: Method, cfg: RunConfig, data: TrainingData, i: int) -> dict[str, Any]:
    """Iteration ``i``: train, evaluate on the training episodes, hand the post-demonstrations
    to the method; its metrics record.

    With a ``--budget``, the rollouts the method learns from are cut at its
    :attr:`~abco_train.methods.base.Method.budget_left` steps (none at all when nothing is
    left), and the record says what is left (``budget_left``) and, after the iteration that
    had nothing left to spend while iterations remained, ``"stopped": "budget"``.

    Raises:
        TrainingFailed: The method's health check failed.
        BudgetExceeded: The method counted past the run's budget.
    """
    t0 = time.perf_counter()
    stats = method.train_iteration(i)
    t_train = time.perf_counter() - t0
    kwargs = episodes(cfg, data, "train", EVAL_SEED)
    # The most steps the runs it learns from may take (None: no budget, or it learns from
    # none, as bc and bco: their evaluation is no interaction and is not cut).
    cap = method.budget_left if method.learns_from_rollouts(i) else None
    explores = method.explores
    roll = rollout(method.act, cfg.env, protocol=cfg.protocol, record=not explores,
                   max_total_steps=None if explores else cap or None, **kwargs)  # fmt: skip
    evaluation = score(roll, data.reference)
    learned: Rollouts | None = roll
    if cap == 0:  # the budget is spent: no post-demonstrations
        learned = None
    elif explores:  # post-demonstrations of its own: the same episodes, explored
        learned = rollout(method.explore, cfg.env, protocol=cfg.protocol, record=True,
                          max_total_steps=cap, **kwargs)  # fmt: skip
    elif roll.budget_cut is not None and roll.budget_cut.any():  # the evaluation, uncut
        evaluation = score(rollout(method.act, cfg.env, protocol=cfg.protocol, **kwargs),
                           data.reference)  # fmt: skip
    spent = method.spent
    post = {} if learned is None else method.observe(i, learned)
    record = {
        "iteration": i, "train": stats, "eval": evaluation, "post": post,
        "label_distribution": _label_distribution(method.expert_labels(), data.n_actions),
        "interactions": dict(method.interactions),
        "seconds_train": t_train, "seconds": time.perf_counter() - t0,
    }  # fmt: skip
    if cfg.budget is not None:
        record["budget_left"] = method.budget_left
        if learned is not None and learned.budget_cut is not None:
            record["budget_cut_runs"] = int(learned.budget_cut.sum())
        # Post-demonstrations counted now feed the next iteration; without them, and with
        # nothing left to spend, more iterations would only repeat this one's training (an
        # offline method's go on training on the datasets: its gradient steps are not cut).
        if (method.online and method.budget_left == 0 and method.spent == spent
                and i + 1 < method.num_iterations):
            record["stopped"] = "budget"
    return record


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
    _write_history(run_dir, [*history, record])
    final = {"env": cfg.env, "method": cfg.method, "seed": cfg.seed,
             **({"layouts": cfg.layouts} if cfg.layouts is not None else {}),
             "task": cfg.task, "budget": cfg.budget, "code_version": code_version(),
             "status": failure.status, "message": str(failure), "iteration": iteration,
             "interactions": interactions,
             "seconds": float(sum(h["seconds"] for h in history))}  # fmt: skip
    write_atomic(run_dir / FINAL, json.dumps(final, indent=2))
    return final


def _write_history(run_dir: Path, history: list[dict[str, Any]]) -> None:
    """``metrics.jsonl``, whole (a full disk leaves the previous one, never a cut line)."""
    write_atomic(run_dir / METRICS, "".join(json.dumps(r) + "\n" for r in history))


def _read_history(path: Path, start: int, n_actions: int) -> list[dict[str, Any]]:
    """The metrics of iterations before ``start``, one per iteration, every one of them. A last
    line cut short (a kill while it was written) is dropped; any other line that is no metrics
    record, or a missing iteration, refuses the resumption.

    Raises:
        RunFolderError: ``metrics.jsonl`` is no regular file, too large, or holds a line that
            is no metrics record (the message names its number).
    """
    if not path.exists():
        return []
    lines = read_capped(path, MAX_JSON_BYTES).decode("utf-8", "replace").splitlines()
    history: dict[int, dict[str, Any]] = {}
    for number, line in enumerate(lines, 1):
        record: Any = None
        try:
            record = json.loads(line)
        except (ValueError, RecursionError):
            if number == len(lines):
                continue  # cut short by a kill; its iteration is in the checkpoint or redone
        if not isinstance(record, dict) or not _is_record(record, n_actions):
            raise RunFolderError(f"{path} line {number} is no metrics record; delete the run "
                                 "folder (or that line) to resume")  # fmt: skip
        if record["iteration"] < start:
            history[record["iteration"]] = record
    missing = [i for i in range(start) if i not in history]
    if missing:  # the checkpoint is after them: their records were written before it
        raise RunFolderError(f"{path} lacks the record of iteration {missing[0]}, which its "
                             "checkpoint follows; delete the run folder to start again")
    return [history[i] for i in range(start)]


def _is_record(record: Any, n_actions: int) -> bool:
    """Whether ``record`` is an iteration's metrics as :func:`_iteration` writes them (as far
    as the plots and ``final.json`` read them)."""
    def number(x: Any) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool)

    def numbers(x: Any, n: int | None = None) -> bool:
        return isinstance(x, list) and all(map(number, x)) and n in (None, len(x))

    if not isinstance(record, dict) or type(record.get("iteration")) is not int:
        return False
    stats, evaluation = record.get("train"), record.get("eval")
    labels, per_class = record.get("label_distribution"), None
    if isinstance(stats, dict):
        per_class = stats.get("idm_val_class_accuracy")
        stats = all(number(stats[k]) for k in ("idm_val_accuracy", "idm_chance") if k in stats)
    return (number(record.get("seconds")) and stats is True and isinstance(evaluation, dict)
            and all(number(evaluation.get(k)) for k in ("performance", "aer", "success_rate"))
            and (labels is None or numbers(labels, n_actions))
            and (per_class is None or numbers(per_class)))
