"""The ``abco`` command: ``train``, ``bench``, ``report``, ``play`` and ``data``.

Every field of :class:`abco_train.config.run.RunConfig` is an option of ``abco train`` and an
override of ``abco bench`` (``--idm-epochs 3``, ``--no-attention``, ...), generated from the
config once (:func:`abco_train.config.run.add_config_options`); unset ones take the defaults of
the env, preset and method.

This module owns the exit codes: 0 success; 2 bad input (an option, a file, a dataset, a
plugin), printed as one ``error: ...`` line; 1 a failed operation (a grid with failed cells,
a disk error). Programming errors keep their traceback. Parsing the command line and
``--help`` import neither torch nor the trainer.

Example:
    >>> args = build_parser().parse_args(["train", "--env", "CartPole-v1", "--idm-epochs", "3"])
    >>> args.env, args.idm_epochs, args.method
    ('CartPole-v1', 3, 'abco')
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from typing import Any

from abco_data.cli import add_subcommands as add_data_subcommands
from abco_data.errors import DatasetError
from abco_train import __version__
from abco_train.config.run import ConfigError, add_config_options, config_from_args

__all__ = ["build_parser", "main"]


def _user_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that mean bad input: printed as one line, exit code 2."""
    from gymnasium.error import DependencyNotInstalled

    from abco_train.bench.backends import BackendError
    from abco_train.harness.run_folder import RunFolderError
    from abco_train.methods.registry import PluginError
    from abco_train.report.write import ReportError

    return (ConfigError, DatasetError, PluginError, ReportError, BackendError, RunFolderError,
            DependencyNotInstalled)  # fmt: skip


# -- abco train ------------------------------------------------------------------------------


def _train(args: argparse.Namespace) -> int:
    from abco_train.methods.registry import load_plugins, resolve_config

    load_plugins(args.plugin)
    config = resolve_config(config_from_args(args))  # every option checked before any work
    from abco_train.harness.loop import format_table, train

    final = train(config)
    if final is None:
        return 0
    if final.get("status", "ok") != "ok":  # the method's health check stopped the run
        print(f"error: {format_table(final)}", file=sys.stderr)
        print(f"run folder: {config.run_dir}", file=sys.stderr)
        return 1
    print(format_table(final))
    print(f"run folder: {config.run_dir}")
    return 0


# -- abco bench ------------------------------------------------------------------------------


def _bench(args: argparse.Namespace) -> int:
    from dataclasses import fields

    from abco_train.bench.grid import (
        CELL_FIELDS,
        parse_layouts,
        parse_list,
        parse_seeds,
        plan,
        run_grid,
    )
    from abco_train.config.run import RunConfig

    overrides = {f.name: getattr(args, f.name) for f in fields(RunConfig)
                 if f.name not in CELL_FIELDS and getattr(args, f.name, None) is not None}
    layouts = [None] if args.layouts is None else parse_layouts(args.layouts)
    cells = plan(parse_list(args.envs), parse_list(args.methods), parse_seeds(args.seeds),
                 layouts)  # fmt: skip
    summary = run_grid(
        cells, args.out, overrides=overrides, method_options=args.method_options,
        plugins=args.plugin, backend=args.backend, jobs=args.jobs, threads=args.threads,
        address=args.address, quiet=args.quiet,
    )  # fmt: skip
    return 1 if summary["failed"] else 0


def _bench_options(parser: argparse.ArgumentParser) -> None:
    from abco_train.bench.backends import BACKENDS

    parser.add_argument("--envs", required=True, help="comma-separated env ids")
    parser.add_argument("--methods", required=True, help="comma-separated method names")
    parser.add_argument("--seeds", default="0-4", help="seeds, e.g. 0-4 or 0,2,5 (default 0-4)")
    parser.add_argument("--layouts", default=None, metavar="K[,K...]",
                        help="mazes 5x5/10x10: one cell per number of training layouts, each "
                        "training on the first K layouts of the procedural datasets, in "
                        "OUT/{env}/{method}/layouts{K}/seed{seed} (e.g. 100,1000,10000; "
                        "default: the standard datasets)")  # fmt: skip
    parser.add_argument("--out", required=True, help="the grid's folder (RUNS_DIR)")
    parser.add_argument("--jobs", type=_positive, default=None,
                        help="cells at once (default: cores)")  # fmt: skip
    parser.add_argument("--backend", choices=BACKENDS, default="local")
    parser.add_argument("--address", default=None, help="Ray cluster address (ray backend)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    group = parser.add_argument_group("trainer overrides (every cell; default: the trainer's)")
    add_config_options(group, exclude=("env", "method", "seed", "layouts", "run_dir", "quiet"),
                       unset_defaults=True)  # fmt: skip


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


# -- abco report -----------------------------------------------------------------------------


def _report(args: argparse.Namespace) -> int:
    from abco_train.report.write import write_report

    files = write_report(args.runs_dir, args.out, args.labels_env, args.baseline)
    print(f"report: {files['report']}\ncsv: {files['csv']}")
    return 0


def _report_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs_dir", help="an `abco bench --out` folder")
    parser.add_argument("--out", default=None, help="output folder (default RUNS_DIR/report)")
    parser.add_argument("--labels-env", default="AbcoMaze5x5-v0",
                        help="env of the IDM label-distribution plot (default the 5x5 maze)")
    parser.add_argument("--baseline", default=None, metavar="METHOD",
                        help="reference method of the probability of improvement (default"
                        " abco); must be a method of the grid")  # fmt: skip


# -- abco play -------------------------------------------------------------------------------


def _play(args: argparse.Namespace) -> int:
    from abco_train.bench.grid import parse_seeds
    from abco_train.harness.trained_policy import load_policy, record_gif

    episodes = parse_seeds(args.episodes)
    policy = load_policy(args.run_dir, quiet=args.quiet)
    out = args.out or str(args.run_dir).rstrip("/") + f"/play_{args.split}.gif"
    path = record_gif(policy, out, episodes, split=args.split, max_steps=args.max_steps,
                      fps=args.fps, progress=not args.quiet)  # fmt: skip
    print(f"animation: {path}")
    return 0


def _play_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", help="a run folder written by abco train")
    parser.add_argument("--episodes", default="0-3",
                        help="mazes: layout indices of the split; classic control: reset seeds"
                        " (e.g. 0-3 or 0,5; default 0-3)")  # fmt: skip
    parser.add_argument("--split", choices=("train", "test"), default="train",
                        help="maze split (default train)")  # fmt: skip
    parser.add_argument("--out", default=None, help="GIF to write (default RUN_DIR/play_SPLIT.gif)")
    parser.add_argument("--max-steps", type=_positive, default=200,
                        help="cap on each episode's length (default 200)")  # fmt: skip
    parser.add_argument("--fps", type=_positive, default=8, help="frames per second (default 8)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


# -- the parser and the entry point ------------------------------------------------------------


def _subcommand(sub: Any, name: str, help: str, options: Callable[[Any], None],
                func: Callable[[argparse.Namespace], int], plugins: bool = True) -> None:
    parser = sub.add_parser(name, help=help, description=help, allow_abbrev=False)
    options(parser)
    if plugins:
        parser.add_argument("--plugin", action="append", default=[], metavar="MODULE_OR_FILE",
                            help="import a module or .py file first (it may register methods)")
    parser.set_defaults(func=func)


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``abco``: ``train``, ``bench``, ``report``, ``play`` and ``data``."""
    parser = argparse.ArgumentParser(prog="abco", description="ABCO: imitation from observation")
    parser.add_argument("--version", action="version", version=f"abco {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _subcommand(sub, "train", "train and evaluate a method on an environment",
                add_config_options, _train)  # fmt: skip
    _subcommand(sub, "bench", "run an (env, method, seed) grid of training runs under "
                "OUT/{env}/{method}/seed{seed}; finished cells are skipped", _bench_options,
                _bench)  # fmt: skip
    _subcommand(sub, "report", "tables and plots of an abco bench grid", _report_options,
                _report, plugins=False)  # fmt: skip
    _subcommand(sub, "play", "roll a trained policy out and write an animated GIF", _play_options,
                _play)  # fmt: skip
    add_data_subcommands(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``abco`` console script and ``python -m abco_train``."""
    args = build_parser().parse_args(argv)
    if args.command == "data":
        from abco_data.cli import run

        return run(args)
    try:
        return int(args.func(args))
    except _user_errors() as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted; re-run the same command to resume", file=sys.stderr)
        return 130
