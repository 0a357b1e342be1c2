"""``abco bench``: the (env, method, seed) grid, each cell an independent training run.

Every cell is :func:`abco_train.train.train` with the trainer's defaults (plus the overrides
given to the whole grid) in its own run folder ``OUT/{env}/{method}/seed{seed}``:

* a cell whose ``final.json`` exists is skipped, so re-running an interrupted benchmark
  resumes it; a cell with a ``checkpoint.pt`` but no ``final.json`` resumes through the
  trainer's own resuming;
* finished cells are collected, one JSON line per cell, in ``OUT/results.jsonl`` (rewritten
  atomically after every cell; the latest row of a cell wins), and every invocation appends
  its wall time to ``OUT/bench_log.jsonl``.

Backends: ``local`` (default) runs the cells in parallel processes
(:class:`concurrent.futures.ProcessPoolExecutor`, spawn context, one fresh process per cell);
``ray`` submits the same cells as Ray tasks (``pip install abco[ray]``), joining the cluster
at ``--address`` or starting a local Ray instance. A cell's numbers depend only on its config
(seed and torch threads included), never on the backend or the host: each cell runs in a
fresh process seeded by the trainer, with ``threads = cores // jobs`` decided once by the
driver (``--threads`` to fix it, e.g. when a cluster's nodes differ from the driver).

Example:
    >>> parse_seeds("0-2,7")
    [0, 1, 2, 7]
    >>> [c.key for c in plan(["CartPole-v1"], ["bc", "abco"], [0])]
    ['CartPole-v1/bc/seed0', 'CartPole-v1/abco/seed0']
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import os
import socket
import sys
import time
import traceback
from collections.abc import Iterator, Sequence
from dataclasses import MISSING, asdict, dataclass, fields
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

__all__ = [
    "Cell", "parse_seeds", "parse_list", "plan", "cell_config", "load_plugins", "run_cell",
    "result_row", "read_results", "run_grid", "add_subcommands", "build_parser", "main",
    "RESULTS_FILE", "BENCH_LOG", "BACKENDS",
]  # fmt: skip

RESULTS_FILE = "results.jsonl"
BENCH_LOG = "bench_log.jsonl"
BACKENDS = ("local", "ray")
#: Config fields the grid sets per cell (never trainer overrides).
_CELL_FIELDS = ("env", "method", "seed", "run_dir", "quiet", "threads", "method_options")
#: Config fields that may differ between a finished cell and a re-run of the grid.
_RUNTIME_FIELDS = ("quiet", "run_dir", "cache_dir", "threads", "expert_data", "pre_data")


@dataclass(frozen=True)
class Cell:
    """One training run of the grid."""

    env: str
    method: str
    seed: int

    @property
    def key(self) -> str:
        """``env/method/seed{seed}``: the cell's run folder relative to the grid's folder."""
        return f"{self.env}/{self.method}/seed{self.seed}"

    def run_dir(self, out: str | os.PathLike[str]) -> Path:
        """The cell's run folder under ``out``."""
        return Path(out) / self.env / self.method / f"seed{self.seed}"


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``"0-4"``, ``"0,3,5"`` or mixes like ``"0-2,7"`` (order kept, no repeats).

    Raises:
        ValueError: A malformed part or an empty range.
    """
    seeds: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            first, last = (int(lo), int(hi)) if sep else (int(part), int(part))
        except ValueError:
            raise ValueError(f"bad seed range {part!r}; expected e.g. 0-4 or 0,2,5") from None
        if last < first:
            raise ValueError(f"empty seed range {part!r}")
        seeds += [s for s in range(first, last + 1) if s not in seeds]
    if not seeds:
        raise ValueError("no seeds given")
    return seeds


def parse_list(text: str) -> list[str]:
    """Comma-separated names, blanks dropped, order kept, no repeats."""
    out: list[str] = []
    for name in (p.strip() for p in text.split(",")):
        if name and name not in out:
            out.append(name)
    return out


def plan(envs: Sequence[str], methods: Sequence[str], seeds: Sequence[int]) -> list[Cell]:
    """Every (env, method, seed) cell, env-major."""
    return [Cell(e, m, int(s)) for e in envs for m in methods for s in seeds]


def cell_config(
    cell: Cell,
    out: str | os.PathLike[str],
    overrides: dict[str, Any] | None = None,
    threads: int = 1,
    method_options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The keyword arguments of the cell's :class:`abco_train.abco.Config`.

    Args:
        cell: The cell.
        out: The grid's folder.
        overrides: Trainer settings applied to every cell (``None`` values are dropped).
        threads: Torch threads of the cell.
        method_options: ``Config.method_options`` of every cell.

    Raises:
        ValueError: An override of a per-cell field (env, method, seed, run_dir, ...).
    """
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    clash = sorted(set(overrides) & set(_CELL_FIELDS))
    if clash:
        raise ValueError(f"the grid sets {', '.join(clash)} per cell; not an override")
    return {
        **overrides, "env": cell.env, "method": cell.method, "seed": cell.seed,
        "run_dir": str(cell.run_dir(out)), "quiet": True, "threads": int(threads),
        "method_options": dict(method_options or {}),
    }  # fmt: skip


def load_plugins(plugins: Sequence[str]) -> None:
    """Import each plugin: a module name (``my_pkg.my_method``) or a ``.py`` file path.

    Importing a plugin registers its methods (:func:`abco_train.methods.register`). A file is
    imported once, as module ``abco_plugin_{stem}``.
    """
    for plugin in plugins:
        if plugin.endswith(".py"):
            path = Path(plugin).resolve()
            name = f"abco_plugin_{path.stem}"
            if name in sys.modules:
                continue
            spec = importlib.util.spec_from_file_location(name, path)
            if spec is None or spec.loader is None:
                raise ImportError(f"cannot import plugin file {plugin}")
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
        else:
            importlib.import_module(plugin)


def _dataset(ref: str | None, env: str, kind: str, cache_dir: str | None,
             cached_only: bool = False) -> Any:  # fmt: skip
    """A run's dataset the way the trainer finds it: a file path, else an id in the cache.

    With ``cached_only`` a dataset missing from the cache raises instead of being fetched.
    """
    import abco_data

    if ref is not None and Path(ref).is_file():
        return abco_data.open_dataset(ref)
    dataset_id = ref or abco_data.dataset_id(env, kind)
    if cached_only:
        home = Path(cache_dir) if cache_dir else abco_data.data_home()
        return abco_data.open_dataset(home / abco_data.spec(dataset_id).filename)
    return abco_data.load(dataset_id, cache_dir=cache_dir, progress=False)


def _references(config: dict[str, Any], cached_only: bool = False) -> dict[str, Any]:
    """Expert/random reference returns (per split for mazes) and the expert's true actions."""
    import numpy as np

    try:
        ds = _dataset(config.get("expert_data"), config["env"], "expert",
                      config.get("cache_dir"), cached_only)  # fmt: skip
    except Exception as exc:  # the references are informative only
        return {"error": f"{type(exc).__name__}: {exc}"}
    ref = ds.reference
    out: dict[str, Any] = {"expert": float(ref.expert_mean), "random": float(ref.random_mean)}
    if ref.layout_splits is not None:
        splits = np.asarray(ref.layout_splits)
        for split in ("train", "test"):
            mask = splits == split
            if mask.any():
                out[split] = {
                    "expert": float(np.asarray(ref.expert_per_layout)[mask].mean()),
                    "random": float(np.asarray(ref.random_per_layout)[mask].mean()),
                    "layouts": int(mask.sum()),
                }
    actions = np.asarray(ds.actions_of_transitions(idm_eval=True), dtype=np.int64)
    n = int(ds.action_space.n)
    out["expert_actions"] = (np.bincount(actions, minlength=n) / max(len(actions), 1)).tolist()
    return out


def result_row(config: dict[str, Any], final: dict[str, Any] | None, wall_s: float | None,
               cached_only: bool = False, **extra: Any) -> dict[str, Any]:  # fmt: skip
    """One line of ``results.jsonl``: the cell, its final evaluation, references, wall time.

    ``cached_only``: read the references only from datasets already on disk (never fetch).
    """
    return {
        "env": config["env"], "method": config["method"], "seed": int(config["seed"]),
        "run_dir": str(config["run_dir"]), "status": "done" if final is not None else "failed",
        "final": final, "wall_s": wall_s, "threads": config.get("threads"),
        "reference": _references(config, cached_only) if final is not None else None, **extra,
    }  # fmt: skip


def run_cell(config: dict[str, Any], plugins: Sequence[str] = ()) -> dict[str, Any]:
    """Train one cell (in whatever process or Ray worker runs it) and return its row.

    Never raises: a failure comes back as a row with ``status: "failed"`` and the traceback.
    """
    t0 = time.perf_counter()
    host = {"host": socket.gethostname(), "pid": os.getpid()}
    try:
        load_plugins(plugins)
        from abco_train.abco import Config
        from abco_train.train import train

        final = train(Config(**config))
    except Exception as exc:
        row = result_row(config, None, time.perf_counter() - t0, **host)
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc()
        return row
    return result_row(config, final, time.perf_counter() - t0, **host)


def read_results(out: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """The rows of ``out/results.jsonl`` by cell key (the latest row of a cell wins)."""
    path = Path(out) / RESULTS_FILE
    rows: dict[str, dict[str, Any]] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                rows[Cell(row["env"], row["method"], int(row["seed"])).key] = row
    return rows


def _write_results(out: Path, rows: dict[str, dict[str, Any]]) -> None:
    tmp = out / (RESULTS_FILE + ".tmp")
    tmp.write_text("".join(json.dumps(r) + "\n" for r in rows.values()))
    os.replace(tmp, out / RESULTS_FILE)


def _comparable(cfg: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in cfg.items() if k not in _RUNTIME_FIELDS}


def _stale(config: dict[str, Any]) -> list[str]:
    """Settings in which a finished cell's ``config.json`` differs from the requested config."""
    from abco_train.abco import Config

    path = Path(config["run_dir"]) / "config.json"
    if not path.exists():
        return []
    had = _comparable(json.loads(path.read_text()))
    wanted = _comparable(asdict(Config(**config).resolved()))
    return sorted(k for k in set(had) | set(wanted) if had.get(k) != wanted.get(k))


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# -- backends: each yields (task index, row) as cells finish ------------------------------


def _run_local(tasks: list[dict[str, Any]], plugins: Sequence[str], jobs: int
               ) -> Iterator[tuple[int, dict[str, Any]]]:  # fmt: skip
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, max_tasks_per_child=1) as pool:
        futures = {pool.submit(run_cell, t, tuple(plugins)): i for i, t in enumerate(tasks)}
        for future in as_completed(futures):
            i = futures[future]
            try:
                row = future.result()
            except Exception as exc:  # the worker process died (e.g. out of memory)
                row = result_row(tasks[i], None, None, error=f"{type(exc).__name__}: {exc}")
            yield i, row


def _run_ray(tasks: list[dict[str, Any]], plugins: Sequence[str], jobs: int | None,
             address: str | None) -> Iterator[tuple[int, dict[str, Any]]]:  # fmt: skip
    try:
        import ray
    except ImportError:
        raise SystemExit("--backend ray needs ray: pip install 'abco[ray]'") from None
    started = not ray.is_initialized()
    if started:
        if address:
            ray.init(address=address, logging_level="WARNING")
        else:
            ray.init(num_cpus=available_cores(), include_dashboard=False,
                     logging_level="WARNING")  # fmt: skip
    try:
        pending: dict[Any, int] = {}
        remotes: dict[int, Any] = {}  # one remote function per CPU request
        queue = list(range(len(tasks)))
        limit = jobs or len(tasks)
        while queue or pending:
            while queue and len(pending) < limit:
                i = queue.pop(0)
                cpus = int(tasks[i]["threads"])
                if cpus not in remotes:
                    remotes[cpus] = ray.remote(num_cpus=cpus, max_retries=0)(run_cell)
                pending[remotes[cpus].remote(tasks[i], tuple(plugins))] = i
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                i = pending.pop(ref)
                try:
                    row = ray.get(ref)
                except Exception as exc:  # the task's worker died
                    row = result_row(tasks[i], None, None, error=f"{type(exc).__name__}: {exc}")
                yield i, row
    finally:
        if started:
            ray.shutdown()


def run_grid(
    cells: Sequence[Cell],
    out: str | os.PathLike[str],
    *,
    overrides: dict[str, Any] | None = None,
    method_options: dict[str, Any] | None = None,
    plugins: Sequence[str] = (),
    backend: str = "local",
    jobs: int | None = None,
    threads: int | None = None,
    address: str | None = None,
    quiet: bool = False,
) -> dict[str, Any]:
    """Run the unfinished cells of a grid and collect every cell into ``results.jsonl``.

    Args:
        cells: The grid (:func:`plan`).
        out: The grid's folder.
        overrides: Trainer settings for every cell (``Config`` fields).
        method_options: ``Config.method_options`` of every cell.
        plugins: Modules or ``.py`` files to import first (in every worker too).
        backend: ``local`` (processes) or ``ray``.
        jobs: Cells at once (local default: the cores; ray default: as the cluster allows).
        threads: Torch threads per cell (default ``max(1, cores // jobs)``).
        address: Ray cluster to join (``ray`` backend).
        quiet: No progress bar or per-cell lines.

    Returns:
        A summary: cells, ran, skipped, failed (keys), wall_s, and the path of the results.

    Raises:
        ValueError: Unknown backend or method, or finished cells of another config.
    """
    from tqdm.auto import tqdm

    from abco_train.methods import available

    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; expected one of {BACKENDS}")
    load_plugins(plugins)
    unknown = sorted({c.method for c in cells} - set(available()))
    if unknown:
        raise ValueError(f"unknown method(s) {', '.join(unknown)}; registered: "
                         f"{', '.join(available())} (a plugin may register more)")  # fmt: skip
    cores = available_cores()
    local_jobs = max(1, jobs or cores)
    threads = int(threads or max(1, cores // local_jobs))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    configs = [cell_config(c, out, overrides, threads, method_options) for c in cells]
    finished = [(Path(cfg["run_dir"]) / "final.json").exists() for cfg in configs]
    stale = [f"{c.key} ({', '.join(diff)})" for c, cfg, f in zip(cells, configs, finished)
             if f and (diff := _stale(cfg))]  # fmt: skip
    if stale:
        raise ValueError(f"finished cells of another config under {out}: {'; '.join(stale)};"
                         " use another --out or delete them")  # fmt: skip

    rows = read_results(out)
    for cell, cfg, done in zip(cells, configs, finished):
        if done and rows.get(cell.key, {}).get("status") != "done":  # finished outside bench
            final = json.loads((Path(cfg["run_dir"]) / "final.json").read_text())
            rows[cell.key] = result_row(cfg, final, None, cached_only=True)
    todo = [i for i, done in enumerate(finished) if not done]
    tasks = [configs[i] for i in todo]
    _write_results(out, rows)

    t0 = time.perf_counter()
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    failed: list[str] = []
    bar = tqdm(total=len(cells), initial=len(cells) - len(todo), desc="abco bench", unit="cell",
               disable=quiet)  # fmt: skip
    runner = (_run_local(tasks, plugins, min(local_jobs, max(len(tasks), 1))) if backend == "local"
              else _run_ray(tasks, plugins, jobs, address))  # fmt: skip
    if tasks:
        for i, row in runner:
            cell = cells[todo[i]]
            row["backend"] = backend
            rows[cell.key] = row
            _write_results(out, rows)
            bar.update(1)
            if row["status"] != "done":
                failed.append(cell.key)
                bar.write(f"{cell.key}: FAILED ({row.get('error')})")
            elif not quiet:
                score = _headline(row["final"])
                bar.write(f"{cell.key}: P={score['performance']:.3f} AER={score['aer']:.3f}"
                          f" in {row['wall_s']:.1f}s")  # fmt: skip
    bar.close()
    wall = time.perf_counter() - t0
    summary = {
        "started": started, "wall_s": wall, "backend": backend, "jobs": jobs or local_jobs,
        "threads": threads, "cells": len(cells), "ran": len(todo) - len(failed),
        "skipped": len(cells) - len(todo), "failed": failed, "argv": sys.argv[1:],
        "results": str(out / RESULTS_FILE),
    }  # fmt: skip
    with (out / BENCH_LOG).open("a") as f:
        f.write(json.dumps(summary) + "\n")
    if not quiet:
        cell_s = sum(rows[cells[todo[i]].key].get("wall_s") or 0.0 for i in range(len(todo)))
        print(f"{summary['ran']} cells run, {summary['skipped']} skipped, {len(failed)} failed;"
              f" wall {wall:.1f}s (cells {cell_s:.1f}s); results: {summary['results']}")
    return summary


def _headline(final: dict[str, Any]) -> dict[str, float]:
    """The final evaluation of the table: mazes, train split, paper protocol; else episodes."""
    for key in ("train/paper", "episodes"):
        if key in final:
            return final[key]
    return next(v for v in final.values() if isinstance(v, dict) and "performance" in v)


# -- command line ---------------------------------------------------------------------------


def _override_options(parser: argparse.ArgumentParser) -> None:
    """One option per trainer setting (``Config`` field), all defaulting to "not set"."""
    from abco_train.abco import Config

    group = parser.add_argument_group("trainer overrides (every cell; default: trainer's)")
    for f in fields(Config):
        if f.name in _CELL_FIELDS and f.name != "threads":
            continue
        flag = "--" + f.name.replace("_", "-")
        kind = str(f.type)
        if kind.startswith("bool"):
            group.add_argument(flag, action=argparse.BooleanOptionalAction, default=None)
            continue
        caster: Any = int if kind.startswith("int") else float if kind.startswith("float") else str
        default = f.default if f.default is not MISSING else None
        help_text = ("torch threads per cell (default cores // jobs)" if f.name == "threads"
                     else f"default {default}")  # fmt: skip
        group.add_argument(flag, type=caster, default=None, help=help_text)


def _configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--envs", required=True, help="comma-separated env ids")
    parser.add_argument("--methods", required=True, help="comma-separated method names")
    parser.add_argument("--seeds", default="0-4", help="seeds, e.g. 0-4 or 0,2,5 (default 0-4)")
    parser.add_argument("--out", required=True, help="the grid's folder (RUNS_DIR)")
    parser.add_argument("--jobs", type=int, default=None, help="cells at once (default: cores)")
    parser.add_argument("--backend", choices=BACKENDS, default="local")
    parser.add_argument("--address", default=None, help="Ray cluster address (ray backend)")
    parser.add_argument("--plugin", action="append", default=[], metavar="MODULE",
                        help="module or .py file to import first (registers methods)")
    parser.add_argument("--method-options", type=json.loads, default={},
                        help="JSON object: Config.method_options of every cell")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    _override_options(parser)
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from abco_train.abco import Config

    names = {f.name for f in fields(Config)} - set(_CELL_FIELDS)
    overrides = {k: getattr(args, k) for k in names if getattr(args, k, None) is not None}
    try:
        cells = plan(parse_list(args.envs), parse_list(args.methods), parse_seeds(args.seeds))
        summary = run_grid(
            cells, args.out, overrides=overrides, method_options=args.method_options,
            plugins=args.plugin, backend=args.backend, jobs=args.jobs, threads=args.threads,
            address=args.address, quiet=args.quiet,
        )  # fmt: skip
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 1 if summary["failed"] else 0


def add_subcommands(subparsers: Any) -> None:
    """Mount ``bench`` on ``abco``'s subparsers (its action is ``args.func(args) -> exit code``)."""
    parser = subparsers.add_parser(
        "bench", help="run an (env, method, seed) grid of training runs", allow_abbrev=False,
        description="Run every (env, method, seed) cell as an independent training run under"
        " OUT/{env}/{method}/seed{seed}; finished cells are skipped.",
    )  # fmt: skip
    _configure(parser)


def build_parser() -> argparse.ArgumentParser:
    """A stand-alone parser of ``abco bench`` (without the ``bench`` word)."""
    parser = argparse.ArgumentParser(prog="abco bench", allow_abbrev=False)
    _configure(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """``abco bench ...`` (``argv`` without the ``bench`` word)."""
    args = build_parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
