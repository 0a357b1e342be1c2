"""Command line of the dataset layer: ``abco data list|info|generate|download|verify|push``.

``abco_train``'s ``abco`` script mounts these with :func:`add_subcommands`; ``python -m
abco_data`` runs them on their own through :func:`main`. Every action parser sets
``func`` (a callable ``func(args) -> int`` exit code) as its default.

Example:
    >>> main(["list"])  # doctest: +ELLIPSIS
    id ...
    0
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from abco_data.errors import DatasetError

__all__ = ["add_subcommands", "main", "build_parser"]


def _manifest_entry(dataset_id: str) -> Any:
    try:
        from abco_data.manifest import read_manifest

        return read_manifest().entry(dataset_id)
    except (DatasetError, ImportError):
        return None


def _cmd_list(args: argparse.Namespace) -> int:
    from abco_data.manifest import data_home
    from abco_data.registry import DATASET_IDS, spec

    home = Path(args.cache_dir) if args.cache_dir else data_home()
    print(f"{'id':<28} {'env':<18} {'kind':<19} {'published':>12}  cached")
    for ds_id in DATASET_IDS:
        s = spec(ds_id)
        entry = _manifest_entry(ds_id)
        size = f"{entry.size / 1e6:.1f} MB" if entry is not None else "-"
        cached = "yes" if (home / s.filename).is_file() else "no"
        print(f"{ds_id:<28} {s.env_id:<18} {s.kind:<19} {size:>12}  {cached}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from abco_data.dataset import open_dataset
    from abco_data.manifest import data_home
    from abco_data.registry import spec

    if Path(args.id).is_file():
        path, s = Path(args.id), None
    else:
        s = spec(args.id)
        path = (Path(args.cache_dir) if args.cache_dir else data_home()) / s.filename
    if s is not None:
        print(f"id:          {s.id}\nenv:         {s.env_id}\nkind:        {s.kind}")
        print(f"filename:    {s.filename}\nparameters:  {json.dumps(dict(s.params))}")
        entry = _manifest_entry(s.id)
        if entry is not None:
            print(f"published:   {entry.size} bytes, sha256 {entry.sha256}")
    if path.is_file():
        ds = open_dataset(path)
        ref = ds.reference
        print(f"file:        {path}\ndataset id:  {ds.id}")
        print(f"episodes:    {ds.num_episodes}\ntransitions: {ds.num_transitions}")
        print(f"observation: {ds.observation_space}\naction:      {ds.action_space}")
        palette = ds.observation_palette
        print(f"storage:     observations {ds.attrs['observation_encoding']}"
              + (f" ({len(palette)} colours)" if palette is not None else ""))
        print(f"reference:   expert {ref.expert_mean:.4f}, random {ref.random_mean:.4f}"
              + (f" ({len(ref.layout_ids)} layouts)" if ref.layout_ids else ""))
        ds.close()
    else:
        print(f"file:        not cached ({path})")
    return 0


def _parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--set expects KEY=VALUE, got {item!r}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def _cmd_generate(args: argparse.Namespace) -> int:
    from abco_data.files import sha256_of
    from abco_data.generate import generate

    start = time.perf_counter()
    path = generate(args.id, args.out, progress=not args.quiet, **_parse_overrides(args.set))
    seconds = time.perf_counter() - start
    print(f"{args.id}: wrote {path} ({path.stat().st_size} bytes, sha256 {sha256_of(path)})"
          f" in {seconds:.1f} s")
    return 0


def _cmd_download(args: argparse.Namespace) -> int:
    from abco_data.hub import download

    path = download(args.id, cache_dir=args.cache_dir, revision=args.revision,
                    progress=not args.quiet)
    print(path)
    return 0


def _cmd_verify(args: argparse.Namespace) -> int:
    from abco_data.dataset import open_dataset
    from abco_data.verify import verify

    path = Path(args.path)
    sha256, size, source = args.sha256, None, "--sha256"
    if sha256 is None:
        ds = open_dataset(path)
        overridden = json.loads(ds.attrs.get("overrides", "[]"))
        entry = None if overridden else _manifest_entry(ds.id)
        ds.close()
        if entry is not None:
            sha256, size, source = entry.sha256, entry.size, "the manifest"
    report = verify(path, sha256=sha256, size=size)
    checked = f"; size and sha256 match {source}" if sha256 else ""
    print(f"OK {report.path}: {report.dataset_id}, {report.num_episodes} episodes,"
          f" {report.num_transitions} transitions, {report.size} bytes, sha256"
          f" {report.sha256}{checked}"
          + (f"; {report.frames_rendered} frames re-rendered" if report.frames_rendered else ""))
    return 0


def _cmd_push(args: argparse.Namespace) -> int:
    from abco_data.publish import push

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
    p = sub.add_parser("verify", help="read and check every value of a dataset file")
    p.add_argument("path")
    p.add_argument("--sha256", help="expected sha256 (default: the manifest's, if listed)")
    p.set_defaults(func=_cmd_verify)
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
    parser = argparse.ArgumentParser(prog="python -m abco_data", description=__doc__
                                     .split("\n")[0])
    _add_actions(parser.add_subparsers(dest="data_command", required=True, metavar="ACTION"))
    return parser


def run(args: argparse.Namespace) -> int:
    """Run a parsed action; dataset errors print one line and give exit code 1."""
    try:
        return int(args.func(args))
    except (DatasetError, FileNotFoundError, TypeError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m abco_data``."""
    return run(build_parser().parse_args(argv))
