"""The ``abco`` command: ``train``, ``bench``, ``tune``, ``report``, ``play``,
``convert-checkpoint`` and ``data``.

Every field of :class:`abco_train.config.run.RunConfig` is an option of ``abco train`` and an
override of ``abco bench`` (``--batch-size 32``, ``--no-attention``, ...), generated from the
config once (:func:`abco_train.config.run.add_config_options`); so is every option of the
method (``abco train --method abco --help``: ``--idm-epochs 3``; ILPO's and GAIfO's carry
their method's prefix, ``--ilpo-latents``), also settable as ``--method-options`` JSON. Unset
ones take the defaults of the env, preset and method.

This module owns the exit codes: 0 success; 2 bad input (an option, a file, a dataset, a
plugin), printed as one ``error: ...`` line; 1 a failed operation (a grid with failed cells,
a disk error: an ``OSError`` with an errno, a full disk or a read-only folder, printed as one
line naming the file); 130 interrupted; 141 stdout closed early (``abco ... | head``: quiet).
Programming errors keep their traceback. Parsing the command line and ``--help`` import
neither torch nor the trainer.

Example:
    >>> argv = ["train", "--env", "CartPole-v1", "--idm-epochs", "3"]
    >>> args = build_parser(argv).parse_args(argv)
    >>> args.env, args.method, _option_flags(args)
    ('CartPole-v1', 'abco', {'idm_epochs': 3})
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

from abco_data.cli import EXIT_BROKEN_PIPE
from abco_data.cli import add_subcommands as add_data_subcommands
from abco_data.cli import run as run_data  # its own exit codes for dataset errors
from abco_data.errors import DatasetError
from abco_train import __version__
from abco_train.cli_play import add_play_options, play
from abco_train.config.fields import check_fields, count
from abco_train.config.limits import MAX_JOBS
from abco_train.config.run import ConfigError, add_config_options, config_from_args
from abco_train.report.command import add_report_options, report
from abco_train.tune.command import add_tune_options, run_tune

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


#: Where the method options' flags land in the parsed namespace (apart from the run config's).
OPTION_DEST = "method_option__"


def _option_flags(args: argparse.Namespace) -> dict[str, Any]:
    """``--method-options`` JSON with the method options given as flags of their own on top;
    a method's own flag (``--lapo-schedule``) keeps its prefix (``lapo-schedule``): it is that
    method's option only (:func:`abco_train.methods.registry.scoped_options`)."""
    flags = {k[len(OPTION_DEST):]: v for k, v in vars(args).items()
             if k.startswith(OPTION_DEST) and v is not None}  # fmt: skip
    return {**(args.method_options or {}), **flags}


def _method_options_of_train(args: argparse.Namespace) -> dict[str, Any]:
    """``abco train``'s method options (its parser holds the flags of its method only)."""
    from abco_train.methods.registry import scoped_options

    return scoped_options(args.method, _option_flags(args))


def _add_method_options(parser: argparse.ArgumentParser, options: Sequence[type],
                        title: str) -> None:  # fmt: skip
    """One group of flags per options class (each flag once, the first class's)."""
    from dataclasses import fields

    from abco_train.config.fields import add_field_options, flag_of

    seen: set[str] = set()
    for cls in dict.fromkeys(options):
        names = [f.name for f in fields(cls)]
        fresh = [n for n in names if flag_of(n, cls.flag_prefix) not in seen]
        if not fresh:
            continue
        group = parser.add_argument_group(f"{title}: {cls.__name__} (also --method-options keys)")
        add_field_options(group, cls, exclude=set(names) - set(fresh), unset_defaults=True,
                          prefix=cls.flag_prefix, dest_prefix=OPTION_DEST + cls.flag_prefix,
                          shown_default="per env and preset")  # fmt: skip
        seen.update(flag_of(n, cls.flag_prefix) for n in fresh)


def _train(args: argparse.Namespace) -> int:
    from abco_train.methods.registry import load_plugins, resolve_config

    load_plugins(args.plugin)
    config = config_from_args(args, method_options=_method_options_of_train(args))
    config = resolve_config(config)  # every option checked before any work
    from abco_train.harness.evaluation import format_table
    from abco_train.harness.loop import train

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

    from abco_train.bench.grid import CELL_FIELDS, run_grid
    from abco_train.config.run import RunConfig

    overrides = {f.name: getattr(args, f.name) for f in fields(RunConfig)
                 if f.name not in CELL_FIELDS and getattr(args, f.name, None) is not None}
    threads = {} if args.threads is None else {"threads": args.threads}
    check_fields(RunConfig(**overrides, **threads))  # types and bounds, before the grid's plan
    track, cells = _bench_plan(args)
    tuned = None
    if args.choices is not None:
        from abco_train.methods.registry import load_plugins
        from abco_train.tune.record import load_choices

        if track is None:
            raise ConfigError("--choices applies to a --track grid (it was tuned on one)")
        load_plugins(args.plugin)  # a plugin method's search space is checked too
        tuned = load_choices(args.choices, track)
    summary = run_grid(
        cells, args.out, overrides=overrides, method_options=_option_flags(args),
        plugins=args.plugin, backend=args.backend, jobs=args.jobs, threads=args.threads,
        address=args.address, quiet=args.quiet, track=track, tuned=tuned,
    )  # fmt: skip
    if summary["failed"]:  # the cells' own lines are above; the one error line says so
        from abco_train.bench.grid import failed_text

        print(f"error: {failed_text(summary)}", file=sys.stderr)
        return 1
    return 0


def _bench_plan(args: argparse.Namespace) -> tuple[Any, list[Any]]:
    """The track (or ``None``) and the cells of ``abco bench``'s command line.

    Raises:
        ConfigError: Neither or both of --envs and --track, a bad list, an unknown task.
    """
    from abco_train.bench.grid import (
        load_track,
        parse_layouts,
        parse_list,
        parse_seeds,
        plan,
        plan_track,
    )

    if (args.envs is None) == (args.track is None):
        raise ConfigError("give --envs (a grid of environments) or --track (a grid of tasks)")
    if args.track is None:
        for flag, given in (("--tasks", args.tasks), ("--budget-multiples",
                                                         args.budget_multiples)):
            if given is not None:
                raise ConfigError(f"{flag} applies to a --track grid")
        layouts = [None] if args.layouts is None else parse_layouts(args.layouts)
        seeds = parse_seeds(args.seeds or "0-4")
        return None, plan(parse_list(args.envs), parse_list(args.methods or ""), seeds, layouts)
    if args.layouts is not None:
        raise ConfigError("--layouts is a setting of a track's tasks, not of the grid")
    track = load_track(args.track)
    if args.budget_multiples is not None:  # the budget curves' points: TASK@xM for each task
        from abco_train.bench.tasks import budget_variants

        track = budget_variants(track, parse_list(args.budget_multiples),
                                parse_list(args.tasks) if args.tasks else None)  # fmt: skip
    methods = parse_list(args.methods) if args.methods else list(track.methods)
    tasks = parse_list(args.tasks) if args.tasks and args.budget_multiples is None else []
    seeds, own = track.grid_seeds(args.seeds or "validation")
    return track, plan_track(track, tasks, methods, seeds, own)


def _bench_options(parser: argparse.ArgumentParser) -> None:
    from abco_train.bench.backends import BACKENDS, available_cores

    parser.add_argument("--envs", default=None, help="comma-separated env ids")
    parser.add_argument("--track", default=None, metavar="NAME|FILE.toml",
                        help="a grid of a track's tasks instead of --envs: a built-in track "
                        "(headline) or a track file; cells in OUT/{task}/{method}/seed{seed}")
    parser.add_argument("--tasks", default=None,
                        help="with --track: comma-separated tasks (default: all)")
    parser.add_argument("--methods", default=None,
                        help="comma-separated method names (default with --track: its methods)")
    parser.add_argument("--seeds", default=None,
                        help="seeds, e.g. 0-4 or 0,2,5 (default 0-4); with --track also "
                        "'validation' (the default) or 'test', the track's own seeds")
    parser.add_argument("--layouts", default=None, metavar="K[,K...]",
                        help="mazes 5x5/10x10: one cell per number of training layouts, each "
                        "training on the first K layouts of the procedural datasets, in "
                        "OUT/{env}/{method}/layouts{K}/seed{seed} (e.g. 100,1000,10000; "
                        "default: the standard datasets)")  # fmt: skip
    parser.add_argument("--budget-multiples", default=None, metavar="M[,M...]",
                        help="with --track: a budget curve's points instead of the tasks, "
                        "each task as TASK@xM with M times its budget (and any method option "
                        "set to the budget, GAIfO's rl_steps, with it), e.g. 4,16")
    parser.add_argument("--choices", default=None, metavar="CHOICES.json",
                        help="with --track: the settings `abco tune` chose for each method "
                        "and task family (its choices.json); options given here win")
    parser.add_argument("--out", required=True, help="the grid's folder (RUNS_DIR)")
    parser.add_argument("--jobs", type=count(MAX_JOBS), default=None,
                        help=f"cells at once, at most {MAX_JOBS} (default: the cores, "
                        f"{available_cores()} here); each cell gets cores / jobs torch threads "
                        "(at least 1) unless --threads says otherwise")  # fmt: skip
    parser.add_argument("--backend", choices=BACKENDS, default="local")
    parser.add_argument("--address", default=None, help="Ray cluster address (ray backend)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    group = parser.add_argument_group("trainer overrides (every cell; default: the trainer's)")
    add_config_options(group, exclude=("env", "method", "seed", "layouts", "run_dir", "quiet"),
                       unset_defaults=True)  # fmt: skip
    from abco_train.methods.registry import builtin_options

    _add_method_options(parser, list(builtin_options().values()),
                        "method options (every cell whose method has them)")


def _train_options(method: str) -> Callable[[argparse.ArgumentParser], None]:
    """``abco train``'s options: the run config's, then ``method``'s own."""

    def options(parser: argparse.ArgumentParser) -> None:
        from abco_train.methods.registry import method_names, options_class

        add_config_options(parser)
        for action in parser._actions:  # every method registered now, plugins' included
            if action.dest == "method":
                action.help = (f"a registered method: {', '.join(method_names())}, or a "
                               "plugin's (--plugin) (default: %(default)s)")
        try:
            cls = options_class(method)
        except ConfigError:  # an unknown method: refused, with the list, when the run starts
            return
        _add_method_options(parser, [cls], f"options of --method {method}")

    return options


def _method_named(argv: Sequence[str]) -> str:
    """The ``--method`` of a command line (the default where none is given); plugins named
    by ``--plugin`` are imported first, so that a plugin method's options are flags too."""
    from abco_train.config.run import RunConfig

    method, plugins = RunConfig.method, []
    for i, arg in enumerate(argv):
        for flag in ("--method", "--plugin"):
            value = argv[i + 1] if arg == flag and i + 1 < len(argv) else \
                arg.split("=", 1)[1] if arg.startswith(flag + "=") else None  # fmt: skip
            if value is not None and flag == "--method":
                method = value
            elif value is not None:
                plugins.append(value)
    if plugins:  # its methods' options become flags, its names join the help's list
        from abco_train.methods.registry import PluginError, load_plugins

        with contextlib.suppress(PluginError):  # said as one error line when the run starts
            load_plugins(plugins)
    return method


# -- abco convert-checkpoint -----------------------------------------------------------------

#: The help of ``abco convert-checkpoint``: unpickling can run code.
CONVERT_HELP = ("rewrite a run folder's checkpoint from the old pickled format into the data-only "
                "one; only for run folders you trust: the old format can run code")  # fmt: skip


def _convert_checkpoint(args: argparse.Namespace) -> int:
    from abco_train.harness.checkpoint import convert_legacy_checkpoint

    path = convert_legacy_checkpoint(args.run_dir)
    print(f"checkpoint: {path} (data only)")
    return 0


def _convert_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", help="a run folder written by an older abco (one you trust)")


# -- the parser and the entry point ------------------------------------------------------------


def _subcommand(sub: Any, name: str, help: str, options: Callable[[Any], None],
                func: Callable[[argparse.Namespace], int], plugins: bool = True) -> None:
    parser = sub.add_parser(name, help=help, description=help, allow_abbrev=False)
    options(parser)
    if plugins:
        parser.add_argument("--plugin", action="append", default=[], metavar="MODULE_OR_FILE",
                            help="import a module or .py file that registers methods, first "
                            "(it runs as code: only plugins you trust)")  # fmt: skip
    parser.set_defaults(func=func)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The parser of ``abco``: ``train``, ``bench``, ``tune``, ``report``, ``play``,
    ``convert-checkpoint`` and ``data``.

    Args:
        argv: The command line to be parsed: its ``--method`` decides which method's options
            ``abco train`` offers (default: ``abco``'s).
    """
    parser = argparse.ArgumentParser(prog="abco", description="ABCO: imitation from observation")
    parser.add_argument("--version", action="version", version=f"abco {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _subcommand(sub, "train", "train and evaluate a method on an environment",
                _train_options(_method_named(list(argv or []))), _train)  # fmt: skip
    _subcommand(sub, "bench", "run an (env, method, seed) grid of training runs under "
                "OUT/{env}/{method}/seed{seed}; finished cells are skipped", _bench_options,
                _bench)  # fmt: skip
    _subcommand(sub, "tune", "the same number of Optuna trials for every method of a track, on "
                "its validation seeds and layouts", add_tune_options, run_tune)  # fmt: skip
    _subcommand(sub, "report", "tables and plots of an abco bench grid", add_report_options,
                report, plugins=False)  # fmt: skip
    _subcommand(sub, "play", "roll a trained policy out and write an animated GIF",
                add_play_options, play)  # fmt: skip
    _subcommand(sub, "convert-checkpoint", CONVERT_HELP, _convert_options, _convert_checkpoint,
                plugins=False)  # fmt: skip
    add_data_subcommands(sub)
    return parser


def _failure(err: Exception) -> tuple[int, str] | None:
    """The exit code and the message of an error that ends a command in one line: bad input
    (2) or a failed operation (1: a disk error, ``OSError`` with an errno); ``None`` for any
    other error, a programming error whose traceback is kept."""
    from abco_data.errors import DatasetWriteError

    if isinstance(err, DatasetWriteError):  # bad luck with the disk, not bad input
        return 1, str(err)
    if isinstance(err, _user_errors()):
        return 2, str(err)
    if isinstance(err, OSError) and err.errno is not None:
        files = " -> ".join(str(f) for f in (err.filename, err.filename2) if f is not None)
        reason = err.strerror or os.strerror(err.errno)
        hint = ("; free some space and run the same command again"
                if err.errno in (errno.ENOSPC, errno.EDQUOT) else "")  # fmt: skip
        return 1, f"{reason}: {files}{hint}" if files else f"{reason}{hint}"
    return None


def _stdout_closed() -> bool:
    """Whether stdout's reader went away (``abco ... | head``): its pipe no longer takes what
    is left to write, or polls as an error (a pipe without a reader; the write that failed
    may have emptied the buffer)."""
    import select

    try:
        sys.stdout.flush()
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poller.poll(0))
    except BrokenPipeError:
        return True
    except (AttributeError, OSError, ValueError):  # no poll (Windows), no file behind stdout
        return False


def _run(args: argparse.Namespace) -> int:
    try:
        return int(run_data(args) if args.command == "data" else args.func(args))
    except KeyboardInterrupt:
        print("interrupted; re-run the same command to resume", file=sys.stderr)
        return 130
    except Exception as err:
        failure = _failure(err)
        if failure is None or (isinstance(err, BrokenPipeError) and _stdout_closed()):
            raise
        print(f"error: {failure[1]}", file=sys.stderr)
        return failure[0]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``abco`` console script and ``python -m abco_train``."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        code = _run(build_parser(argv).parse_args(argv))
        sys.stdout.flush()  # a reader gone shows here, not as a message at exit
        return code
    except BrokenPipeError:
        if not _stdout_closed():
            raise
        with contextlib.suppress(OSError, ValueError):  # no more writes to the closed pipe
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
