"""Wall time of training runs on an idle machine and beside one competing CPU-bound process.

Each run is the ``abco train`` command line in a fresh process and a fresh run folder (datasets
generated once, up front, into a scratch cache). The competing process is a pure-Python busy
loop: one core's worth of load, the situation of a laptop or a shared 2-core CI machine.
Settings compared: torch threads (``--threads``) and deterministic kernels on or off.

Usage::

    python benchmarks/bench_load.py        # 5x5 ABCO (the README main job) and CartPole
    python benchmarks/bench_load.py --envs CartPole-v1 --threads 1,2 --tiny

Prints one row per (env, threads, deterministic): idle seconds, loaded seconds, loaded / idle.
The goal: the main job and CartPole within 2x of their idle time under that load.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BUSY = "while True:\n    pass\n"
TINY = ["--iterations", "0", "--idm-epochs", "1", "--policy-epochs", "1", "--eval-episodes", "5",
        "--eval-layouts", "5", "--no-plots"]  # fmt: skip


def run(env: str, threads: int, deterministic: bool, cache: Path, out: Path, tiny: bool) -> float:
    """Seconds of one ``abco train`` run (process start to exit)."""
    cmd = [sys.executable, "-m", "abco_train", "train", "--env", env, "--method", "abco",
           "--seed", "0", "--threads", str(threads), "--quiet", "--run-dir", str(out),
           "--cache-dir", str(cache), "--deterministic" if deterministic else "--no-deterministic",
           *(TINY if tiny else [])]  # fmt: skip
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--envs", default="AbcoMaze5x5-v0,CartPole-v1")
    parser.add_argument("--threads", default="1,2", help="torch threads to compare")
    parser.add_argument("--deterministic", default="on,off", help="on, off or both")
    parser.add_argument("--tiny", action="store_true",
                        help="a smoke run: CartPole only, 1 thread, deterministic, tiny budget")
    args = parser.parse_args()
    if args.tiny:
        args.envs, args.threads, args.deterministic = "CartPole-v1", "1", "on"
    envs = [e for e in args.envs.split(",") if e]
    threads = [int(t) for t in args.threads.split(",") if t]
    modes = [m == "on" for m in args.deterministic.split(",") if m]
    print(f"abco train wall time, idle vs one busy process; {os.cpu_count()} CPUs; "
          f"python {sys.version.split()[0]}")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for env in envs:  # datasets generated once, outside the timings
            run(env, 1, True, root / "cache", root / f"warm-{env}", tiny=True)
        print(f"{'env':<18}{'threads':>8}{'determ.':>9}{'idle s':>9}{'loaded s':>10}{'ratio':>7}")
        for env in envs:
            for t in threads:
                for det in modes:
                    tag = f"{env}-{t}-{int(det)}"
                    idle = run(env, t, det, root / "cache", root / f"idle-{tag}", args.tiny)
                    busy = subprocess.Popen([sys.executable, "-c", BUSY])
                    try:
                        loaded = run(env, t, det, root / "cache", root / f"load-{tag}",
                                     args.tiny)  # fmt: skip
                    finally:
                        busy.kill()
                        busy.wait()
                    print(f"{env:<18}{t:>8}{'on' if det else 'off':>9}{idle:>9.1f}"
                          f"{loaded:>10.1f}{loaded / idle:>7.2f}", flush=True)


if __name__ == "__main__":
    main()
