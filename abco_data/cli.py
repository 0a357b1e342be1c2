"""Command line of the dataset layer: ``abco data list|info|generate|download|verify|push``,
and for the user's own datasets ``record`` and ``import-minari`` (:mod:`abco_data.user.cli`).

``abco_train``'s ``abco`` script mounts these with :func:`add_subcommands`; ``python -m
abco_data`` runs them on their own through :func:`main`. Every action parser sets
``func`` (a callable ``func(args) -> int`` exit code) as its default.

A dataset problem ends in one line ``error: ...`` on stderr, never a traceback: exit status 2
for bad input (an unknown id, a bad ``--set``, a file that does not exist or is of another
kind, a count beyond its bound, an output path that is a device, a FIFO, a folder or a
link), 1 for an operation that failed (a corrupt file, a checksum mismatch, no source for a
dataset, a full disk); an environment whose optional package is missing (LunarLander's
Box2D) names the extra to install, exit status 2. Programming errors keep their traceback.
Output cut short by its reader (``abco data list | head``) ends quietly, with exit status 141
as ``SIGPIPE`` gives.

Example:
    >>> main(["list"])  # doctest: +ELLIPSIS
    id ...
    0
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from gymnasium.error import DependencyNotInstalled

from abco_data.errors import (
    DatasetError,
    DatasetReadError,
    InvalidParameterError,
    InvalidTargetError,
    UnknownDatasetError,
    WrongKindError,
)
from abco_data.user.cli import add_user_actions, print_user_info, user_list_rows
from abco_data.user.ids import is_user_id

__all__ = ["add_subcommands", "main", "build_parser", "run", "EXIT_FAILED", "EXIT_BAD_INPUT",
           "EXIT_BROKEN_PIPE", "UsageError"]

#: Exit status of an operation that failed (corrupt data, no source, a full disk).
EXIT_FAILED = 1
#: Exit status of bad input (as argparse's own usage errors).
EXIT_BAD_INPUT = 2
#: Exit status when the reader of the output went away (as a process killed by ``SIGPIPE``).
EXIT_BROKEN_PIPE = 141
#: Default time limit of ``abco data verify`` (it runs in a child process).
VERIFY_TIMEOUT = 600.0


class UsageError(DatasetError):
    """A command-line argument that cannot be used (exit status 2)."""


def _manifest() -> Any:
    try:
        from abco_data.hub.manifest import read_manifest

        return read_manifest()
    except (DatasetError, ImportError):
        return None


def _manifest_entry(dataset_id: str) -> Any:
    manifest = _manifest()
    return None if manifest is None else manifest.entry(dataset_id)


def _source(manifest: Any, dataset_id: str) -> str:
    """Where :func:`abco_data.load` gets a dataset: the Hub, when the manifest pins a
    revision that holds it; else local generation."""
    published = manifest is not None and manifest.revision and manifest.entry(dataset_id)
    return "Hub" if published else "generated"


def _cmd_list(args: argparse.Namespace) -> int:
    from abco_data.hub.manifest import data_home
    from abco_data.registry import DATASET_IDS, spec

    home = Path(args.cache_dir) if args.cache_dir else data_home()
    manifest = _manifest()
    rows = []
    for ds_id in DATASET_IDS:
        s = spec(ds_id)
        entry = None if manifest is None else manifest.entry(ds_id)
        size = f"{entry.size / 1e6:.1f} MB" if entry is not None else "-"
        cached = "yes" if (home / s.filename).is_file() else "no"
        rows.append((ds_id, s.env_id, s.kind, size, _source(manifest, ds_id), cached))
    rows += user_list_rows(home)  # the user's own datasets, after the built-in ones
    width = max(len(row[0]) for row in rows)
    print(f"{'id':<{width}} {'env':<18} {'kind':<19} {'size':>9}  {'source':<9}  cached")
    for ds_id, env_id, kind, size, source, cached in rows:
        print(f"{ds_id:<{width}} {env_id:<18} {kind:<19} {size:>9}  {source:<9}  {cached}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from abco_data.dataset import open_dataset
    from abco_data.hub.manifest import data_home
    from abco_data.registry import spec

    if args.layouts is not None and args.layouts < 1:  # checked even where nothing is cached
        raise UsageError(f"--layouts must be >= 1, got {args.layouts}")
    if Path(args.id).is_file():
        path, s = Path(args.id), None
    elif is_user_id(args.id):
        s = None
        path = print_user_info(args.id, Path(args.cache_dir) if args.cache_dir else data_home())
    else:
        s = spec(args.id)
        path = (Path(args.cache_dir) if args.cache_dir else data_home()) / s.filename
    if s is not None:
        print(f"id:          {s.id}\nenv:         {s.env_id}\nkind:        {s.kind}")
        print(f"filename:    {s.filename}\nparameters:  {json.dumps(dict(s.params))}")
        entry = _manifest_entry(s.id)
        if entry is not None:
            print(f"bytes:       {entry.size} bytes, sha256 {entry.sha256}")
        where = "the Hub" if _source(_manifest(), s.id) == "Hub" else \
            "generated locally (not published on the Hub)"
        print(f"source:      {where}")
    if path.is_file():
        ds = whole = open_dataset(path)
        if args.layouts is not None:
            try:
                ds = whole.first_layouts(args.layouts)
            except ValueError as err:
                raise UsageError(str(err)) from err
        ref = ds.reference
        print(f"file:        {path}\ndataset id:  {ds.id}")
        if ds.is_maze:
            taken = "" if ds is whole else f" (the first, of {whole.num_layouts})"
            print(f"layouts:     {ds.num_layouts}{taken}")
        print(f"episodes:    {ds.num_episodes}\ntransitions: {ds.num_transitions}")
        print(f"observation: {ds.observation_space}\naction:      {ds.action_space}")
        palette = ds.observation_palette
        print(f"storage:     observations {ds.attrs['observation_encoding']}"
              + (f" ({len(palette)} colours)" if palette is not None else ""))
        print(f"reference:   expert {ref.expert_mean:.4f}, random {ref.random_mean:.4f}"
              + (f" ({len(ref.layout_ids)} layouts)" if ref.layout_ids else ""))
        ds.close()
        whole.close()
    else:
        print(f"file:        not cached ({path})")
    return 0


def _parse_overrides(dataset_id: str, items: Sequence[str], out_path: str | None
                     ) -> dict[str, Any]:
    from abco_data.registry import spec

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise UsageError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    try:
        spec(dataset_id).with_overrides(**out)
    except TypeError as err:  # with_overrides' own report of an unknown parameter
        raise UsageError(str(err)) from err
    if out and out_path is None:
        raise UsageError("--set needs --out: the cache only holds the standard datasets")
    return out


def _cmd_generate(args: argparse.Namespace) -> int:
    from abco_data.format.files import sha256_of
    from abco_data.generation.generate import generate

    overrides = _parse_overrides(args.id, args.set, args.out)
    start = time.perf_counter()
    path = generate(args.id, args.out, progress=not args.quiet, **overrides)
    seconds = time.perf_counter() - start
    print(f"{args.id}: wrote {path} ({path.stat().st_size} bytes, sha256 {sha256_of(path)})"
          f" in {seconds:.1f} s")
    return 0


def _cmd_download(args: argparse.Namespace) -> int:
    from abco_data.hub.fetch import download

    path = download(args.id, cache_dir=args.cache_dir, revision=args.revision,
                    progress=not args.quiet)
    print(path)
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from abco_data.verify import verify

    report = verify(args.source, sha256=args.sha256, timeout=args.timeout)
    checked = f"; size and sha256 match {report.checksum}" if report.checksum else \
        "; no checksum is known for this dataset id"
    print(f"OK {report.path}: {report.dataset_id}, {report.num_episodes} episodes,"
          f" {report.num_transitions} transitions, {report.size} bytes, sha256"
          f" {report.sha256}{checked}"
          + (f"; {report.frames_rendered} frames re-rendered" if report.frames_rendered else ""))
    return 0


def _cmd_push(args: argparse.Namespace) -> int:
    from abco_data.hub.publish import push

    commit = push(args.id, args.repo, path=args.path, revision=args.revision)
    print(f"pushed {args.id} to {args.repo} at {commit}")
    return 0


def _add_actions(sub: Any) -> None:
    p = sub.add_parser("list", help="list the datasets")
    p.add_argument("--cache-dir", help="abco dataset cache (default $ABCO_DATA_HOME)")
    p.set_defaults(func=_cmd_list)
    p = sub.add_parser("info", help="show a dataset's parameters and, if cached, its contents")
    p.add_argument("id", help="dataset id (or the path of a dataset file)")
    p.add_argument("--cache-dir")
    p.add_argument("--layouts", type=int, metavar="K",
                   help="mazes: count the episodes and transitions of the first K layouts only")
    p.set_defaults(func=_cmd_info)
    p = sub.add_parser("generate", help="generate a dataset locally (deterministic bytes)")
    p.add_argument("id")
    p.add_argument("--out", help="target file (default: the cache)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a creation parameter (tests, small variants)")
    p.set_defaults(func=_cmd_generate)
    p = sub.add_parser("download", help="download a published dataset into the cache")
    p.add_argument("id")
    p.add_argument("--cache-dir")
    p.add_argument("--revision")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_download)
    p = sub.add_parser("verify", help="check the bytes and every value of a dataset file")
    p.add_argument("source", metavar="PATH_OR_ID",
                   help="a dataset file, or a dataset id (the cache's copy)")
    p.add_argument("--sha256", help="expected sha256 (default: the manifest's for a published"
                   " file, the generator's bytes for a variant)")
    p.add_argument("--timeout", type=float, default=VERIFY_TIMEOUT,
                   help=f"give up after this many seconds (default {VERIFY_TIMEOUT:g})")
    p.set_defaults(func=_cmd_verify)
    add_user_actions(sub)  # record, import-minari
    p = sub.add_parser("push", help="upload a dataset and its card to a Hub dataset repo")
    p.add_argument("id")
    p.add_argument("--repo", required=True, help="dataset repo, owner/name")
    p.add_argument("--path", help="file to upload (default: the cache's copy)")
    p.add_argument("--revision", help="branch (default main)")
    p.set_defaults(func=_cmd_push)


def add_subcommands(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``data`` command (with its actions) to another program's subparsers."""
    data = subparsers.add_parser("data", help="abco datasets: list, generate, verify, ...")
    _add_actions(data.add_subparsers(dest="data_command", required=True, metavar="ACTION"))
    return data


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m abco_data``."""
    parser = argparse.ArgumentParser(prog="python -m abco_data",
                                     description=(__doc__ or "").split("\n")[0])
    _add_actions(parser.add_subparsers(dest="data_command", required=True, metavar="ACTION"))
    return parser


def run(args: argparse.Namespace) -> int:
    """Run a parsed action; a dataset error prints one line ``error: ...`` and gives exit
    status :data:`EXIT_BAD_INPUT` or :data:`EXIT_FAILED` (see the module docstring)."""
    try:
        status = int(args.func(args))
        sys.stdout.flush()  # a reader gone away shows here, not at exit
        return status
    except BrokenPipeError:
        # Nothing more can reach the reader: point stdout at devnull, so that Python's own
        # flush at exit does not report the broken pipe either.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return EXIT_BROKEN_PIPE
    except (UsageError, UnknownDatasetError, WrongKindError, DatasetReadError,
            InvalidParameterError, InvalidTargetError, DependencyNotInstalled) as err:
        print(f"error: {err}", file=sys.stderr)  # a missing package: the extra to install
        return EXIT_BAD_INPUT
    except DatasetError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m abco_data``."""
    return run(build_parser().parse_args(argv))
