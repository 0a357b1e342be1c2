"""``abco tune``: its options, and the studies they ask for (:func:`.study.tune`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from abco_train.config.fields import count
from abco_train.config.limits import MAX_JOBS, MAX_THREADS

__all__ = ["add_tune_options", "run_tune", "MAX_TRIALS"]

#: The most trials ``--trials`` accepts per method (a bound on the work one command starts).
MAX_TRIALS = 1_000


def add_tune_options(parser: argparse.ArgumentParser) -> None:
    """Add ``abco tune``'s options to ``parser``."""
    from abco_train.tune.space import FAMILIES
    from abco_train.tune.study import BENCHMARK_TRIALS

    parser.add_argument("--track", default="headline", metavar="NAME|FILE.toml",
                        help="the track whose tasks are tuned (default headline)")
    parser.add_argument("--family", required=True, choices=FAMILIES,
                        help="the track's tasks of this kind: classic (vector observations), "
                        "maze or image; one study per method over all of them")  # fmt: skip
    parser.add_argument("--methods", default=None,
                        help="comma-separated methods (default: the track's, less expert and "
                        "random)")  # fmt: skip
    parser.add_argument("--trials", type=count(MAX_TRIALS), default=BENCHMARK_TRIALS,
                        help=f"finished trials per method, the first its defaults (default "
                        f"{BENCHMARK_TRIALS}); a folder that holds some resumes")  # fmt: skip
    parser.add_argument("--out", required=True,
                        help="the tuning folder: optuna.journal, trials.jsonl, choices.json, "
                        "tuning.md and the trials' runs")  # fmt: skip
    parser.add_argument("--seeds", default=None,
                        help="the validation seeds a trial runs, some of the track's (e.g. "
                        "100; default: all of them); every trial of a method's study runs "
                        "the same: give every method the same")  # fmt: skip
    parser.add_argument("--jobs", type=count(MAX_JOBS), default=None,
                        help="a trial's cells at once (default: the cores)")
    parser.add_argument("--threads", type=count(MAX_THREADS), default=None,
                        help="torch threads per cell (default: cores / jobs, at least 1)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")


def run_tune(args: argparse.Namespace) -> int:
    """Run ``abco tune``; print each method's trials and best value."""
    from abco_train.bench.cells import parse_list, parse_seeds
    from abco_train.bench.tasks import load_track
    from abco_train.config.fields import ConfigError
    from abco_train.report.headline import REFERENCE_METHODS
    from abco_train.tune.study import TuneSpec, tune

    try:
        import optuna  # noqa: F401
    except ImportError:
        raise ConfigError("abco tune needs Optuna: pip install 'abco[tune]'") from None
    from abco_train.methods.registry import load_plugins

    load_plugins(args.plugin)  # a plugin method's options are its search space
    track = load_track(args.track)
    methods = parse_list(args.methods) if args.methods else [
        m for m in track.methods if m not in REFERENCE_METHODS]  # fmt: skip
    if not methods:
        raise ConfigError("no method to tune")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {args.out!r} is not a folder")
    spec = TuneSpec(track, args.family, tuple(methods), args.trials, out, args.jobs,
                    args.threads, args.quiet, tuple(args.plugin),
                    tuple(parse_seeds(args.seeds)) if args.seeds else None)  # fmt: skip
    for method, done in tune(spec).items():
        print(f"{args.family}/{method}: {done['trials']} trials, best {done['best']:.3f} "
              f"(trial {done['best_trial']})")
    print(f"tuning record: {out / 'tuning.md'}")
    return 0
