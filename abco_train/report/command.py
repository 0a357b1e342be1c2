"""``abco report``: its options, and the report or the tuning record they ask for.

``abco report RUNS_DIR`` writes the report of a grid (:func:`abco_train.report.write.write_report`,
with ``--budget-curves`` its budget curves); ``abco report TUNING --tuning A,B`` the tuning
record of validation grids (:func:`abco_train.report.tuning.write_tuning`).
"""

from __future__ import annotations

import argparse

from abco_train.config.fields import ConfigError

__all__ = ["add_report_options", "report"]


def report(args: argparse.Namespace) -> int:
    """Run ``abco report`` (its options from :func:`add_report_options`); print what it wrote."""
    from abco_train.report.write import write_report

    if args.tuning is not None:
        return _tuning(args)
    if args.track is not None:
        raise ConfigError("--track applies only with --tuning (the track of a tuning record)")
    files = write_report(args.runs_dir, args.out, args.labels_env, args.baseline,
                         args.budget_curves, args.tuned_by)  # fmt: skip
    print(f"report: {files['report']}\ncsv: {files['csv']}")
    return 0


def _tuning(args: argparse.Namespace) -> int:
    from abco_train.bench.cells import parse_list, parse_seeds
    from abco_train.bench.tasks import load_track
    from abco_train.report.tuning import write_tuning

    if args.budget_curves is not None:
        raise ConfigError("--budget-curves belongs to a report, not to a --tuning record")
    track = load_track("headline" if args.track is None else args.track)
    if not track.validation_seeds:
        raise ConfigError(f"track {track.name} names no validation seeds")
    files = write_tuning(args.runs_dir, parse_list(args.tuning), track,
                         parse_seeds(track.validation_seeds), args.out)  # fmt: skip
    print(f"tuning record: {files['record']}\nchoices: {files['choices']}")
    return 0


def add_report_options(parser: argparse.ArgumentParser) -> None:
    """Add ``abco report``'s arguments and options to ``parser``."""
    parser.add_argument("runs_dir", help="an `abco bench --out` folder")
    parser.add_argument("--out", default=None, help="output folder (default RUNS_DIR/report)")
    parser.add_argument("--labels-env", default="AbcoMaze5x5-v0",
                        help="env of the IDM label-distribution plot (default the 5x5 maze)")
    parser.add_argument("--baseline", default=None, metavar="METHOD",
                        help="reference method of the probability of improvement (default"
                        " abco); must be a method of the grid")  # fmt: skip
    parser.add_argument("--budget-curves", default=None, metavar="CURVES_DIR",
                        help="a grid of budget variants of the track's tasks (TASK@xMULTIPLE):"
                        " their score-against-budget curves, the 1x points from RUNS_DIR")
    parser.add_argument("--tuned-by", default=None, metavar="TUNING_DIR",
                        help="an `abco tune --out` folder: the tuning effort of the grid's "
                        "methods (trials per method and task family, on which seeds)")
    parser.add_argument("--tuning", default=None, metavar="CONFIG[,CONFIG...]",
                        help="write the tuning record of RUNS_DIR instead: one validation grid"
                        " per configuration in RUNS_DIR/CONFIG, the defaults first")
    parser.add_argument("--track", default=None, metavar="NAME|FILE.toml",
                        help="the track of --tuning (default headline)")
