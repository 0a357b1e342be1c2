"""The user's own datasets on the command line: ``abco data record`` and ``abco data
import-minari``, and the user datasets' rows of ``abco data list`` and lines of ``info``.

:mod:`abco_data.cli` mounts these (:func:`add_user_actions`) and reports their errors as
every other action's: one line ``error: ...``, exit status 2 for bad input, 1 for a failed
operation.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from abco_data.errors import InvalidParameterError

__all__ = ["add_user_actions", "user_list_rows", "print_user_info"]


def _json_object(text: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise InvalidParameterError(f"--env-kwargs is not JSON: {err}") from None
    if not isinstance(value, dict):
        raise InvalidParameterError(f"--env-kwargs must be a JSON object, got {text!r}")
    return value


def _report(path: Path, dataset_id: str | None, seconds: float) -> None:
    from abco_data.dataset import open_dataset
    from abco_data.format.files import sha256_of
    from abco_data.user.datasets import user_manifest_path

    ds = open_dataset(path)
    print(f"{ds.id}: wrote {path} ({path.stat().st_size} bytes, sha256 {sha256_of(path)}),"
          f" {ds.num_episodes} episodes, {ds.num_transitions} transitions, reference expert"
          f" {ds.reference.expert_mean:.4f}, random {ds.reference.random_mean:.4f}, in"
          f" {seconds:.1f} s" + (f"; registered in {user_manifest_path()}" if dataset_id
                                 else ""))
    ds.close()


def _cmd_record(args: argparse.Namespace) -> int:
    from abco_data.user.record import record

    start = time.perf_counter()
    path = record(args.env, args.policy, kind=args.kind, episodes=args.episodes,
                  transitions=args.transitions, seed=args.seed, out=args.out, id=args.id,
                  env_kwargs=_json_object(args.env_kwargs),
                  max_episode_steps=args.max_episode_steps,
                  reference_episodes=args.reference_episodes,
                  reference_expert_episodes=args.reference_expert_episodes,
                  sb3_algo=args.sb3_algo, overwrite=args.overwrite, progress=not args.quiet)
    _report(path, args.id, time.perf_counter() - start)
    return 0


def _cmd_import_minari(args: argparse.Namespace) -> int:
    from abco_data.interop.minari_import import import_minari

    start = time.perf_counter()
    path = import_minari(args.source, out=args.out, id=args.id, kind=args.kind,
                         download=args.download, reference_episodes=args.reference_episodes,
                         overwrite=args.overwrite, progress=not args.quiet)
    _report(path, args.id, time.perf_counter() - start)
    return 0


def _add_target(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", metavar="FILE", help="the file to write (with --id: registered"
                   " there; without: it holds the id local/<file name>-v0)")
    p.add_argument("--id", metavar="ID", help="a user dataset id, NAMESPACE/NAME-vN (e.g."
                   " local/cartpole-mine-v0), registered in the user manifest of the data"
                   " home; without --out the file goes into the data home")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a registered user dataset of the same id")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def add_user_actions(sub: Any) -> None:
    """Add ``record`` and ``import-minari`` to the ``data`` actions' subparsers."""
    p = sub.add_parser("record", help="record a dataset of your own policy on any Gymnasium env")
    p.add_argument("--env", required=True, metavar="ENV_ID",
                   help="Gymnasium id; module:Id-v0 imports the module first")
    p.add_argument("--policy", metavar="MODULE:CALLABLE|MODEL.zip",
                   help="a policy on one observation (MODULE: a .py file or a dotted module)"
                   " or a Stable-Baselines3 model; default for --kind pre: uniform random"
                   " actions")
    p.add_argument("--sb3-algo", metavar="NAME", help="the algorithm of an SB3 model (PPO,"
                   " DQN, ...; default: read from the model)")
    p.add_argument("--kind", choices=("expert", "pre"), required=True)
    count = p.add_mutually_exclusive_group(required=True)
    count.add_argument("--episodes", type=int, metavar="N", help="record N whole episodes")
    count.add_argument("--transitions", type=int, metavar="N",
                       help="record N transitions (the last episode cut)")
    p.add_argument("--seed", type=int, default=0, help="episode i is reset with SEED + i")
    p.add_argument("--max-episode-steps", type=int, metavar="N",
                   help="a step limit for the env (needed when it has none)")
    p.add_argument("--env-kwargs", default="{}", metavar="JSON",
                   help="keyword arguments of gymnasium.make, a JSON object")
    p.add_argument("--reference-episodes", type=int, default=100, metavar="N",
                   help="random-policy episodes of the random reference return")
    p.add_argument("--reference-expert-episodes", type=int, default=20, metavar="N",
                   help="episodes of the policy for the expert reference return")
    _add_target(p)
    p.set_defaults(func=_cmd_record)
    p = sub.add_parser("import-minari", help="import a Minari dataset as an abco dataset")
    p.add_argument("source", metavar="DATASET_ID_OR_PATH",
                   help="a Minari dataset id, or the folder of a Minari dataset")
    p.add_argument("--kind", choices=("expert", "pre"), default="expert")
    p.add_argument("--download", action="store_true",
                   help="let Minari download a dataset it does not hold")
    p.add_argument("--reference-episodes", type=int, default=100, metavar="N",
                   help="random-policy episodes of the random reference, where the dataset"
                   " has no ref_min_score")
    _add_target(p)
    p.set_defaults(func=_cmd_import_minari)


def user_list_rows(home: Path) -> list[tuple[str, str, str, str, str, str]]:
    """``(id, env, kind, size, source, cached)`` of each registered user dataset."""
    from abco_data.user.datasets import read_user_manifest

    return [(e.dataset_id, e.env_id, e.kind, f"{e.size / 1e6:.1f} MB", "user",
             "yes" if e.path.is_file() else "missing")
            for e in read_user_manifest(home).values()]


def print_user_info(dataset_id: str, home: Path) -> Path:
    """Print what the user manifest says of ``dataset_id``; return its file.

    Raises:
        UnknownDatasetError: Not registered.
    """
    from abco_data.errors import UnknownDatasetError
    from abco_data.user.datasets import user_entry, user_manifest_path

    entry = user_entry(dataset_id, home)
    if entry is None:
        raise UnknownDatasetError(f"unknown dataset id {dataset_id!r}: no user dataset of"
                                  f" that id is registered in {user_manifest_path(home)}")
    print(f"id:          {entry.dataset_id}\nenv:         {entry.env_id}\nkind:"
          f"        {entry.kind}")
    print(f"bytes:       {entry.size} bytes, sha256 {entry.sha256}")
    print(f"source:      user dataset (registered in {user_manifest_path(home)})")
    return entry.path
