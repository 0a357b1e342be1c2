"""Quality and speed of the trainer's CPU defaults: ABCO, one seed, each env in turn.

Targets (issue 4): ABCO on ``AbcoMaze5x5-v0`` reaches P >= 0.96 on the train split within
10 minutes of wall time; on ``CartPole-v1`` P = 1.0 within 1 minute. The other envs are
reported. Datasets are fetched (or generated) before the clock starts, so the time is the
training run itself: data loading into memory, every iteration, and the final evaluation.

Usage::

    python benchmarks/bench_train.py                      # the two targets
    python benchmarks/bench_train.py --envs all           # all six envs
    python benchmarks/bench_train.py --envs Acrobot-v1 --method bco --out /tmp/bench
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import abco_data
import abco_envs
from abco_train.config import RunConfig
from abco_train.train import train

#: env -> (minimum train P, maximum seconds)
TARGETS = {"AbcoMaze5x5-v0": (0.96, 600.0), "CartPole-v1": (1.0, 60.0)}
ALL_ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)


def main() -> int:
    """Run the benchmark and print one line per env; exit code 1 if a target is missed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--envs", default="AbcoMaze5x5-v0,CartPole-v1",
                        help="comma-separated env ids, or 'all'")  # fmt: skip
    parser.add_argument("--method", default="abco")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/bench_train")
    parser.add_argument("--data-dir", default=None,
                        help="generate the standard datasets into this folder with"
                        " abco_data.generate and train on those files (default:"
                        " abco_data.load, i.e. cache, Hub or local generation)")  # fmt: skip
    args = parser.parse_args()
    envs = ALL_ENVS if args.envs == "all" else tuple(args.envs.split(","))

    rows, missed = [], False
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
        final = train(RunConfig(env=env, method=args.method, seed=args.seed, run_dir=str(run_dir),
                             quiet=True, expert_data=files.get("expert"),
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
        if env in TARGETS and args.method == "abco":
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
