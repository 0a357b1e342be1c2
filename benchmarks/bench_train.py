"""Quality and speed of the trainer's CPU defaults: ABCO, one seed, each env in turn.

Targets: ABCO on ``AbcoMaze5x5-v0`` reaches P >= 0.96 on the train split within
10 minutes of wall time; on ``CartPole-v1`` P = 1.0 within 1 minute. The other envs are
reported. Datasets are fetched (or generated) before the clock starts, so the time is the
training run itself: data loading into memory, every iteration, and the final evaluation.

Usage::

    python benchmarks/bench_train.py                      # the two targets
    python benchmarks/bench_train.py --envs all           # all six envs
    python benchmarks/bench_train.py --envs Acrobot-v1 --method bco --out /tmp/bench
    python benchmarks/bench_train.py --tiny               # seconds: a smoke test, no targets

``--tiny`` trains through the ``abco train`` command line only (``python -m abco_train
train``, one iteration of one epoch on a few hundred transitions, 2 evaluation episodes or
layouts of at most 10 steps), on the standard datasets generated into a temporary folder
unless ``--data-dir`` is given, by default on AbcoMaze3x3-v0 (the quickest to generate) and
CartPole-v1; its figures mean nothing and no target is judged.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import abco_data
import abco_envs
from abco_train.config.run import RunConfig
from abco_train.harness.loop import train

#: env -> (minimum train P, maximum seconds)
TARGETS = {"AbcoMaze5x5-v0": (0.96, 600.0), "CartPole-v1": (1.0, 60.0)}
ALL_ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)
#: ``abco train`` options of ``--tiny``: one short iteration, a tiny evaluation.
TINY_OPTIONS = ("--iterations", "0", "--first-epochs-factor", "1", "--idm-epochs", "1",
                "--policy-epochs", "1", "--pre-transitions", "256", "--expert-episodes", "4",
                "--eval-episodes", "2", "--eval-layouts", "2", "--eval-max-steps", "10",
                "--no-plots", "--quiet")


def train_cli(env: str, method: str, seed: int, run_dir: Path, files: dict[str, str]) -> dict:
    """One tiny run through ``python -m abco_train train``; its ``final.json``."""
    cmd = [sys.executable, "-m", "abco_train", "train", "--env", env, "--method", method,
           "--seed", str(seed), "--run-dir", str(run_dir), *TINY_OPTIONS]
    for kind, option in (("expert", "--expert-data"), ("pre_demonstrations", "--pre-data")):
        if kind in files:
            cmd += [option, files[kind]]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads((run_dir / "final.json").read_text())


def main() -> int:
    """Run the benchmark and print one line per env; exit code 1 if a target is missed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--envs", default=None,
                        help="comma-separated env ids, or 'all' (default: the two targets'"
                        " envs; with --tiny AbcoMaze3x3-v0,CartPole-v1)")  # fmt: skip
    parser.add_argument("--method", default="abco")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None,
                        help="run folders and bench_train.json (default: runs/bench_train;"
                        " with --tiny a temporary folder, removed)")  # fmt: skip
    parser.add_argument("--data-dir", default=None,
                        help="generate the standard datasets into this folder with"
                        " abco_data.generate and train on those files (default:"
                        " abco_data.load, i.e. cache, Hub or local generation)")  # fmt: skip
    parser.add_argument("--tiny", action="store_true",
                        help="seconds-long runs through the abco train command line (a smoke"
                        " test: no target judged)")  # fmt: skip
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="bench_train_")) if args.tiny else None
    if scratch is not None:
        args.data_dir = args.data_dir or str(scratch / "data")
        args.out = args.out or str(scratch / "runs")
    args.out = args.out or "runs/bench_train"
    args.envs = args.envs or ("AbcoMaze3x3-v0,CartPole-v1" if args.tiny else ",".join(TARGETS))
    try:
        return bench(args)
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)


def bench(args: argparse.Namespace) -> int:
    """Train on each env in turn, print a row each; 1 if a target is missed."""
    envs = ALL_ENVS if args.envs == "all" else tuple(args.envs.split(","))

    rows, missed = [], False
    print(f"{'env':<18} {'method':<10} result (P: train split, paper protocol on mazes)",
          flush=True)
    for env in envs:
        files = {}
        for kind in ("expert", "pre_demonstrations"):  # outside the timed part
            ds_id = abco_data.dataset_id(env, kind)
            if args.data_dir is None:
                abco_data.load(ds_id, progress=False)
                continue
            path = Path(args.data_dir) / f"{ds_id.split('/')[1]}.hdf5"
            if not path.exists():
                abco_data.generate(ds_id, path, progress=False)
            files[kind] = str(path)
        run_dir = Path(args.out) / f"{env}-{args.method}-s{args.seed}"
        shutil.rmtree(run_dir, ignore_errors=True)
        start = time.perf_counter()
        if args.tiny:
            final = train_cli(env, args.method, args.seed, run_dir, files)
        else:
            final = train(RunConfig(env=env, method=args.method, seed=args.seed,
                                    run_dir=str(run_dir), quiet=True,
                                    expert_data=files.get("expert"),
                                    pre_data=files.get("pre_demonstrations")))  # fmt: skip
        seconds = time.perf_counter() - start
        main_key = "train/paper" if env in abco_envs.MAZE_IDS else "episodes"
        m = final[main_key]
        row = {"env": env, "method": args.method, "seed": args.seed, "seconds": seconds,
               "P": m["performance"], "AER": m["aer"], "success": m["success_rate"]}
        if env in abco_envs.MAZE_IDS:
            row.update({f"P_{k.replace('/', '_')}": final[k]["performance"]
                        for k in ("train/standard", "test/paper", "test/standard")})
        status = ""
        if env in TARGETS and args.method == "abco" and not args.tiny:
            min_p, max_s = TARGETS[env]
            ok = m["performance"] >= min_p - 1e-9 and seconds <= max_s
            missed |= not ok
            status = f"target P>={min_p} in {max_s:.0f}s: {'met' if ok else 'MISSED'}"
        rows.append(row)
        extra = "".join(f" {k}={v:.3f}" for k, v in row.items() if k.startswith("P_"))
        print(f"{env:<18} {args.method:<10} P={m['performance']:.3f} AER={m['aer']:.3f} "
              f"success={m['success_rate']:.2f} time={seconds:.0f}s{extra}  {status}",
              flush=True)  # fmt: skip
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "bench_train.json").write_text(json.dumps(rows, indent=2))
    return 1 if missed else 0


if __name__ == "__main__":
    raise SystemExit(main())
