"""Peak memory and wall time of training on the first K layouts of the procedural mazes.

Each run is the ``abco train`` command line in a fresh process and a fresh run folder::

    abco train --env AbcoMaze5x5-v0 --layouts 10000 --preset general

Its peak resident set size is the kernel's high-water mark of the child's memory
(``VmHWM`` of ``/proc/PID/status``, read every 0.2 s; it only grows, so the last reading is the
peak), printed with the time it was reached. Not ``ru_maxrss``: a child started by
``subprocess`` inherits the launching process's peak there (the memory it had before ``exec``);
where ``/proc`` is missing (macOS) that is the figure, with that caveat. The wall time runs from
process start to exit, the CPU time (user and system: on a shared machine, steadier than wall
time) comes from ``os.wait4``, and the training time per iteration from the run's
``metrics.jsonl`` (``seconds_train``, evaluation excluded). The datasets are fetched or
generated before the clock starts.

``--baseline DIR`` runs the same commands on another checkout of abco as well (a ``git
worktree`` of an earlier commit, say), one run at a time, and prints this checkout's figures
as ratios of that one's. Training decodes nothing up front: maze frames stay (layout,
position) pairs and are drawn a minibatch at a time, so memory grows with the datasets'
episodes, not with their frames.

Usage::

    python benchmarks/memory_training.py                        # 5x5 and 10x10, K = 10,000
    python benchmarks/memory_training.py --envs AbcoMaze5x5-v0 --baseline /tmp/abco-old
    python benchmarks/memory_training.py --train-args "--iterations 0"   # a shorter run
    python benchmarks/memory_training.py --tiny                 # seconds: a smoke test

``--tiny`` trains on 10 layouts of small procedural datasets generated into a temporary
folder, with one short iteration; its figures mean nothing and no goal is judged.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: env -> peak resident set size goal in bytes (the full command, K = 10,000).
GOALS = {"AbcoMaze5x5-v0": 1_000_000_000, "AbcoMaze10x10-v0": 2_000_000_000}
#: Training time per iteration may be at most this much above the baseline's.
TIME_GOAL = 1.10
#: ``abco train`` options of ``--tiny``: one short iteration, a tiny evaluation.
TINY_OPTIONS = ("--iterations", "0", "--idm-epochs", "1", "--policy-epochs", "1",
                "--first-epochs-factor", "1", "--eval-layouts", "2", "--eval-max-steps", "10",
                "--method-options", '{"min_updates": 2, "max_updates": 2}')  # fmt: skip
TINY_LAYOUTS = 10


def measure(code: Path, env: str, args: argparse.Namespace, run_dir: Path,
            files: dict[str, str]) -> dict[str, float | int]:  # fmt: skip
    """One ``abco train`` run of the checkout ``code``: peak RSS, seconds (wall, CPU), train
    seconds per iteration."""
    cmd = [sys.executable, "-m", "abco_train", "train", "--env", env, "--layouts",
           str(args.layouts), "--preset", args.preset, "--method", args.method, "--seed", "0",
           "--run-dir", str(run_dir), "--quiet", "--no-plots", *shlex.split(args.train_args)]
    for option, path in files.items():
        cmd += [option, path]
    if args.cache_dir:
        cmd += ["--cache-dir", args.cache_dir]
    environ = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(code), *filter(None, [os.environ.get("PYTHONPATH")])])}
    start = time.perf_counter()
    child = subprocess.Popen(cmd, env=environ, stdout=subprocess.DEVNULL)
    peak, peak_at = 0, 0.0
    while True:
        pid, status, usage = os.wait4(child.pid, os.WNOHANG)
        if pid:
            break
        now = high_water(child.pid)
        if now > peak:
            peak, peak_at = now, time.perf_counter() - start
        time.sleep(0.2)
    seconds = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
    train = []
    metrics = run_dir / "metrics.jsonl"
    if metrics.exists():
        train = [json.loads(line)["seconds_train"] for line in metrics.read_text().splitlines()
                 if line.strip()]  # fmt: skip
    if not peak:  # no /proc: ru_maxrss (bytes on macOS), which counts the launcher's too
        peak, peak_at = usage.ru_maxrss * (1 if sys.platform == "darwin" else 1024), seconds
    return {"rss": peak, "peak_at": peak_at, "seconds": seconds, "code": child.returncode,
            "cpu": usage.ru_utime + usage.ru_stime,
            "iterations": len(train), "train_per_iter": sum(train) / max(len(train), 1)}


def high_water(pid: int) -> int:
    """Peak resident bytes of process ``pid`` so far (``VmHWM``), or 0 where unreadable."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def tiny_files(root: Path, env: str) -> dict[str, str]:
    """Small procedural datasets of ``env`` (12 layouts), generated into ``root``."""
    import abco_data
    from abco_data.registry import procedural_dataset_id

    files = {}
    for kind, option in (("expert", "--expert-data"), ("pre", "--pre-data")):
        ds_id = procedural_dataset_id(env, kind)
        path = root / f"{ds_id.split('/')[1]}.hdf5"
        if not path.exists():
            abco_data.generate(ds_id, path, progress=False, layouts=TINY_LAYOUTS + 2,
                               reference_episodes=2)  # fmt: skip
        files[option] = str(path)
    return files


def fetch(env: str, cache_dir: str | None) -> None:
    """Fetch (or generate) the env's procedural datasets before any clock starts."""
    import abco_data
    from abco_data.registry import procedural_dataset_id

    for kind in ("expert", "pre"):
        abco_data.load(procedural_dataset_id(env, kind), cache_dir=cache_dir, progress=True)


def row(label: str, m: dict[str, float | int]) -> str:
    failed = "" if m["code"] == 0 else f"  (exit {m['code']})"
    return (f"{label:<30}{m['rss'] / 2**30:>10.2f}{m['peak_at']:>9.0f}{m['seconds']:>9.0f}"
            f"{m['cpu']:>8.0f}{m['iterations']:>6}{m['train_per_iter']:>13.1f}{failed}")


def run_all(envs: list[str], checkouts: list[tuple[str, Path]], args: argparse.Namespace,
            scratch: Path) -> tuple[bool, bool]:  # fmt: skip
    """Every (env, checkout) run, one at a time, printed as it ends; ``(failed, missed)``:
    whether a run failed, whether a judged goal was missed."""
    failed = missed = False
    for env in envs:
        files = tiny_files(scratch / "data", env) if args.tiny else {}
        if not args.tiny:
            fetch(env, args.cache_dir)
        results = {}
        for label, code in checkouts:
            run_dir = scratch / f"{env}-{label.replace(' ', '-')}"
            results[label] = m = measure(code, env, args, run_dir, files)
            print(row(f"{env} {label}", m), flush=True)
            failed |= m["code"] != 0
        now = results["this checkout"]
        if "baseline" in results:
            old = results["baseline"]
            time_ratio = now["train_per_iter"] / max(old["train_per_iter"], 1e-9)
            print(f"{'':<4}ratio this / baseline: peak {now['rss'] / old['rss']:.3f}, wall"
                  f" {now['seconds'] / old['seconds']:.3f}, CPU {now['cpu'] / old['cpu']:.3f},"
                  f" train s/iter {time_ratio:.3f}")
            if not args.tiny and time_ratio > TIME_GOAL:
                missed = True
        goal = GOALS.get(env)
        if goal and not args.tiny and not args.train_args:
            ok = now["rss"] <= goal
            missed |= not ok
            print(f"{'':<4}goal: peak <= {goal / 1e9:.0f} GB: {'met' if ok else 'MISSED'}")
    return failed, missed


def main() -> int:
    """Run the measurements and print one row per (env, checkout); exit 1 if a run fails or
    a judged goal is missed."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--envs", default=",".join(GOALS))
    parser.add_argument("--layouts", type=int, default=10_000, help="K (default 10,000)")
    parser.add_argument("--method", default="abco")
    parser.add_argument("--preset", default="general")
    parser.add_argument("--train-args", default="",
                        help="more abco train options, e.g. '--iterations 0' (goals are judged"
                        " on the full command only)")  # fmt: skip
    parser.add_argument("--baseline", default=None,
                        help="another checkout of abco to run the same commands on, for ratios")
    parser.add_argument("--cache-dir", default=None, help="abco dataset cache")
    parser.add_argument("--tiny", action="store_true",
                        help="seconds-long runs on 10 layouts of small generated datasets")
    args = parser.parse_args()
    envs = [e for e in args.envs.split(",") if e]
    scratch = Path(tempfile.mkdtemp(prefix="memory_training_"))
    if args.tiny:
        args.layouts, args.train_args = TINY_LAYOUTS, shlex.join(TINY_OPTIONS)
        envs = envs[:1]
    checkouts = [("this checkout", ROOT)]
    if args.baseline:
        checkouts.insert(0, ("baseline", Path(args.baseline).resolve()))
    print(f"abco train --layouts {args.layouts} --preset {args.preset} --method {args.method}"
          f" {args.train_args}; {os.cpu_count()} CPUs")
    print(f"{'env / checkout':<30}{'peak GiB':>10}{'at s':>9}{'wall s':>9}{'CPU s':>8}"
          f"{'iters':>6}{'train s/iter':>13}")
    try:
        failed, missed = run_all(envs, checkouts, args, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    print("goals: not judged (--tiny or --train-args)" if args.tiny or args.train_args
          else "goals: peak RSS 5x5 <= 1 GB, 10x10 <= 2 GB; train s/iter <= 1.10 x baseline")
    return 1 if failed or missed else 0


if __name__ == "__main__":
    sys.exit(main())
