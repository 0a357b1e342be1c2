"""The ``abco`` command: ``abco train ...`` and ``abco data ...``.

Every field of :class:`abco_train.abco.Config` is an option of ``abco train`` (``--idm-epochs
3``, ``--no-attention``, ...); unset ones take the env's and preset's defaults.

Example:
    >>> parser = build_parser()
    >>> args = parser.parse_args(["train", "--env", "CartPole-v1", "--idm-epochs", "3"])
    >>> args.env, args.idm_epochs, args.method
    ('CartPole-v1', 3, 'abco')
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from collections.abc import Sequence
from dataclasses import MISSING, fields
from typing import Any

import abco_envs
from abco_data.errors import DatasetError

__all__ = ["build_parser", "main"]

_HELP = {
    "env": "environment id (AbcoMaze3x3/5x5/10x10-v0, CartPole-v1, Acrobot-v1, MountainCar-v0)",
    "method": "method: bc, bco, bco-alpha, abco, attention, sampling-partial, sampling-whole,"
    " abco-whole, or a plugged-in one",
    "preset": "cpu (compact CNN for images, the default) or paper (the paper's ResNet-18)",
    "iterations": "alpha: iterations 0..alpha are run",
    "protocol": "maze evaluation protocol during training: paper (4th visit ends, -1) or standard",
}


def _train_options(parser: argparse.ArgumentParser) -> None:
    from abco_train.abco import Config

    for f in fields(Config):
        if f.name == "method_options":
            continue
        flag = "--" + f.name.replace("_", "-")
        default = f.default if f.default is not MISSING else None
        kind = str(f.type)
        help_text = _HELP.get(f.name, f.name.replace("_", " "))
        if kind.startswith("bool"):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=default,
                                help=help_text)  # fmt: skip
            continue
        caster: Any = str
        if kind.startswith("int"):
            caster = int
        elif kind.startswith("float"):
            caster = float
        parser.add_argument(flag, type=caster, default=default, help=help_text)
    parser.add_argument("--method-options", type=json.loads, default={},
                        help="JSON object of options for a plugged-in method")  # fmt: skip
    parser.add_argument("--plugin", action="append", default=[], metavar="MODULE",
                        help="import MODULE first (it may register more methods)")  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``abco``: ``train``, ``bench``, ``report`` and ``data``."""
    parser = argparse.ArgumentParser(prog="abco", description="ABCO: imitation from observation")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    train = sub.add_parser("train", help="train and evaluate a method on an environment")
    _train_options(train)
    from abco_data.cli import add_subcommands
    from abco_train import bench, report

    add_subcommands(sub)
    bench.add_subcommands(sub)
    report.add_subcommands(sub)
    return parser


def _run_train(args: argparse.Namespace) -> int:
    from abco_train.abco import Config

    for module in args.plugin:
        importlib.import_module(module)
    values = {f.name: getattr(args, f.name) for f in fields(Config)}
    from abco_train.methods import available
    from abco_train.train import format_table, train

    if values["method"] not in available():
        print(f"error: unknown method {values['method']!r}; registered: "
              f"{', '.join(available())}", file=sys.stderr)  # fmt: skip
        return 2
    known_envs = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)
    if values["env"] not in known_envs:
        print(f"error: unknown env id {values['env']!r}; abco trains on: "
              f"{', '.join(known_envs)}", file=sys.stderr)  # fmt: skip
        return 2
    config = Config(**values)
    try:
        final = train(config)
    except DatasetError as err:  # a bad dataset file or id: the message names it
        print(f"error: {err}", file=sys.stderr)
        return 2
    if final is not None:
        print(format_table(final))
        print(f"run folder: {config.resolved().run_dir}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``abco`` console script and ``python -m abco_train``."""
    args = build_parser().parse_args(argv)
    if args.command == "train":
        return _run_train(args)
    from abco_data.cli import run

    return run(args)
