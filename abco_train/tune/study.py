"""One Optuna study per method and task family: the same trials for every method.

A study is named ``{family}/{method}``; its trial 0 runs the method's defaults (enqueued with
no settings), the later ones draw from :func:`~abco_train.tune.space.method_space` with
Optuna's TPE sampler (seeded with :data:`SAMPLER_SEED` plus the trials so far, so that a
resumed study draws what an uninterrupted one would). A trial runs the family's tasks of the
track on its validation seeds (:func:`~abco_train.bench.grid.run_grid`: maze runs on
validation layouts) and scores the mean headline score of those runs, a failed or missing
run counting 0.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from abco_train.bench.cells import parse_seeds, plan_track
from abco_train.bench.tasks import Track
from abco_train.config.fields import ConfigError
from abco_train.config.run import env_kind
from abco_train.tune.record import journal, write_record
from abco_train.tune.space import (
    FAMILIES,
    method_space,
    resolved_options,
    split_params,
    suggest,
)

__all__ = ["TuneSpec", "SAMPLER_SEED", "STARTUP_TRIALS", "BENCHMARK_TRIALS",
           "family_tasks", "tune", "trial_runs"]  # fmt: skip

SAMPLER_SEED = 0
#: Trials drawn at random (after the defaults) before TPE models the results.
STARTUP_TRIALS = 4
#: Trials per method and family of the benchmark's rule (``abco tune``'s default); a report
#: flags a method tuned with fewer.
BENCHMARK_TRIALS = 8


@dataclass(frozen=True)
class TuneSpec:
    """What ``abco tune`` runs: every method of ``methods`` on ``family``'s tasks of
    ``track``, ``trials`` trials each, its record in ``out``."""

    track: Track
    family: str
    methods: tuple[str, ...]
    trials: int
    out: Path
    jobs: int | None = None
    threads: int | None = None
    quiet: bool = False
    plugins: tuple[str, ...] = ()
    #: Some of the track's validation seeds (``None``: all of them).
    seeds: tuple[int, ...] | None = None


def family_tasks(track: Track, family: str) -> list[str]:
    """The tasks of ``track`` whose env is of ``family``.

    Raises:
        ConfigError: An unknown family, or one the track has no task of.
    """
    if family not in FAMILIES:
        raise ConfigError(f"unknown --family {family!r}; one of {', '.join(FAMILIES)}")
    tasks = [t.name for t in track.tasks if env_kind(t.env) == family]
    if not tasks:
        kinds = sorted({env_kind(t.env) for t in track.tasks})
        raise ConfigError(f"track {track.name} has no {family} task; its families: "
                          f"{', '.join(kinds)}")  # fmt: skip
    return tasks


def tune(spec: TuneSpec) -> dict[str, Any]:
    """Run every method's study of ``spec`` up to ``spec.trials`` finished trials (resuming
    what ``spec.out`` holds) and write the record after each trial.

    Returns:
        ``method -> {"trials": n, "best": value, "best_trial": k}``.

    Raises:
        ConfigError: No validation seeds, an unknown family, no trial.
    """
    import optuna

    if not spec.track.validation_seeds:
        raise ConfigError(f"track {spec.track.name} names no validation seeds to tune on")
    if spec.trials < 1:
        raise ConfigError("--trials must be at least 1")
    seeds = _trial_seeds(spec)
    tasks = family_tasks(spec.track, spec.family)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    spec.out.mkdir(parents=True, exist_ok=True)
    storage = journal(spec.out)
    done: dict[str, Any] = {}
    for method in spec.methods:
        study = optuna.create_study(study_name=f"{spec.family}/{method}", storage=storage,
                                    direction="maximize", load_if_exists=True)  # fmt: skip
        _requeue_unfinished(study)
        _check_same_seeds(study, seeds)
        # the settings some task of the family reads: an epoch count that every task's
        # converged schedule ignores is not searched
        space = method_space(method, resolved_options(spec.track, method, tasks))
        while (finished := _finished(study)) < spec.trials:
            study.sampler = optuna.samplers.TPESampler(
                seed=SAMPLER_SEED + len(study.trials), n_startup_trials=STARTUP_TRIALS + 1)
            _run_trial(study, spec, method, tasks, seeds, finished, space)
            write_record(spec.out, spec.track)
        best = study.best_trial
        done[method] = {"trials": _finished(study), "best": best.value, "best_trial": best.number}
    write_record(spec.out, spec.track)
    return done


def _trial_seeds(spec: TuneSpec) -> list[int]:
    """The validation seeds every trial runs: ``spec.seeds``, all of them some of the
    track's, or the track's.

    Raises:
        ConfigError: A seed that is not one of the track's validation seeds.
    """
    validation = parse_seeds(spec.track.validation_seeds)
    if spec.seeds is None:
        return sorted(validation)
    other = sorted(set(spec.seeds) - set(validation))
    if other:
        raise ConfigError(f"--seeds {', '.join(map(str, other))}: not among track "
                          f"{spec.track.name}'s validation seeds "
                          f"({spec.track.validation_seeds}); a tuning runs on those only")
    return sorted(set(spec.seeds))


def _check_same_seeds(study: Any, seeds: list[int]) -> None:
    """A study's trials all run on the same seeds: a resume with others would compare trials
    scored on different runs.

    Raises:
        ConfigError: A finished trial of the study ran on other seeds.
    """
    for trial in study.trials:
        ran = trial.user_attrs.get("seeds")
        if ran is not None and sorted(ran) != seeds:
            raise ConfigError(f"study {study.study_name} ran its trials on seeds "
                              f"{', '.join(map(str, ran))}; --seeds must name the same "
                              f"(got {', '.join(map(str, seeds))})")  # fmt: skip


def _finished(study: Any) -> int:
    from optuna.trial import TrialState

    return sum(t.state == TrialState.COMPLETE for t in study.trials)


def _requeue_unfinished(study: Any) -> None:
    """A trial left running by a process that died is failed and queued again, with its
    settings and folder (its finished runs are kept); the first trial is the defaults."""
    from optuna.trial import TrialState

    if not study.trials:
        study.enqueue_trial({}, user_attrs={"defaults": True})
    for trial in study.trials:
        if trial.state == TrialState.RUNNING:
            study.tell(trial.number, state=TrialState.FAIL)
            study.enqueue_trial(trial.params, user_attrs=dict(trial.user_attrs))


def _run_trial(study: Any, spec: TuneSpec, method: str, tasks: list[str], seeds: list[int],
               finished: int, space: dict[str, Any]) -> None:  # fmt: skip
    from optuna.trial import TrialState

    trial = study.ask()
    folder = trial.user_attrs.get("folder") or f"trial{trial.number:03d}"
    trial.set_user_attr("folder", folder)
    try:
        params = {} if trial.user_attrs.get("defaults") else suggest(trial, space)
        t0 = time.perf_counter()
        out = spec.out / spec.family / method / folder
        failures = _run_cells(spec, method, tasks, seeds, params, out)
        runs = trial_runs(out, method, tasks, seeds)
    except BaseException:  # interrupted or refused: queued again with the same settings
        study.tell(trial, state=TrialState.FAIL)
        study.enqueue_trial(trial.params, user_attrs=dict(trial.user_attrs))
        raise
    value = float(sum(v or 0.0 for v in runs.values()) / len(runs))
    for key, attr in (("runs", runs), ("failures", failures), ("seeds", seeds),
                      ("tasks", tasks), ("seconds", round(time.perf_counter() - t0, 1))):
        trial.set_user_attr(key, attr)
    study.tell(trial, value)
    if not spec.quiet:
        best = study.best_trial
        print(f"tune {spec.family}/{method}: trial {finished + 1}/{spec.trials} scored "
              f"{value:.3f} (best {best.value:.3f}, trial {best.number})", flush=True)


def _run_cells(spec: TuneSpec, method: str, tasks: list[str], seeds: list[int],
               params: dict[str, Any], out: Path) -> list[str]:  # fmt: skip
    """Run the trial's cells; the failed cells' lines (a failure scores 0)."""
    from abco_train.bench.grid import run_grid

    overrides, options = split_params(method, params)
    cells = plan_track(spec.track, tasks, [method], seeds)
    summary = run_grid(cells, out, overrides=overrides, method_options=options,
                       plugins=spec.plugins, jobs=spec.jobs, threads=spec.threads,
                       quiet=spec.quiet, track=spec.track)  # fmt: skip
    return [f"{key}: {why}" for key, why in summary.get("failures", {}).items()]


def trial_runs(out: Path, method: str, tasks: list[str], seeds: list[int]
               ) -> dict[str, float | None]:  # fmt: skip
    """``{task}/seed{seed} -> headline score`` of a trial's runs (``None``: no result; a run
    its method stopped scores 0, as in the report)."""
    from abco_train.report.headline import split_tracks, task_cells
    from abco_train.report.runs import load_runs

    by_task, _ = split_tracks(load_runs(out, []))
    cells = task_cells(by_task)
    runs: dict[str, float | None] = {}
    for task in tasks:
        cell = cells.get(task, {}).get(method)
        for seed in seeds:
            value = None if cell is None or not cell.scored else cell.values.get(seed)
            runs[f"{task}/seed{seed}"] = (
                value if value is not None and math.isfinite(value) else None)
    return runs
