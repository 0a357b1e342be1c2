"""The GPU check: CUDA tests, then the same headline cells on CUDA and on CPU, side by side.

Meant for a machine with an NVIDIA GPU, run first there and briefly (minutes): it prints the
device torch sees, runs the tests that need CUDA (those marked ``cuda``, in the files that hold
them, :data:`CUDA_TEST_FILES`: no other test module is even imported), then runs one seed of
each method on two headline tasks through ``abco bench`` twice, ``--device auto`` and
``--device cpu`` (the two arms at once: the CPU arm on the CPU cores, the auto arm
``--cuda-jobs`` cells at a time, on the GPU where ``auto`` puts a cell there: image tasks;
vector tasks stay on the CPU), and prints each cell's wall time on both with the
ratio CPU / auto and both scores, and the GPU's utilisation and memory in use while the arms ran
(``nvidia-smi``, sampled every 2 s). Training on CUDA is not bit-identical to CPU, so the scores
may differ a little; a large gap is worth a look. The table goes to ``OUT/gpu_times.csv``
beside the two grids.

Usage::

    python benchmarks/bench_gpu.py --out "$OUT"         # the check (minutes)
    python benchmarks/bench_gpu.py --tasks cartpole-authors-data --methods bc,abco
    python benchmarks/bench_gpu.py --tiny               # seconds: a smoke test, CPU arm only

Without a CUDA device the CUDA tests and arm are skipped and said so; the CPU arm still runs.
``--tiny`` runs two methods on CartPole with one short iteration and a tiny evaluation; its
figures mean nothing.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import time
from pathlib import Path

import torch

from abco_train.bench.results_log import RESULTS_FILE, headline, read_results

ROOT = Path(__file__).resolve().parents[1]
TASKS = "cartpole-authors-data,maze3x3-heldout"
METHODS = "bc,bco,bco-alpha,bco-alpha-torabi,abco,iupe,ilpo,gaifo"
#: ``abco bench`` options of ``--tiny``: one short iteration, a tiny evaluation.
TINY_OPTIONS = ("--iterations", "0", "--first-epochs-factor", "1", "--idm-epochs", "1",
                "--policy-epochs", "1", "--eval-episodes", "2", "--eval-max-steps", "10")


def describe_device() -> bool:
    """Print what torch sees; whether a CUDA device is there."""
    cuda = torch.cuda.is_available()
    name = torch.cuda.get_device_name(0) if cuda else "none"
    print(f"torch {torch.__version__}, CUDA build {torch.version.cuda}, CUDA device: {name}")
    return cuda


#: The test files that hold the tests marked ``cuda`` (a test of this repository checks that
#: no other file has one).
CUDA_TEST_FILES = ("tests/train/test_train_cli.py",)


def cuda_tests(out: Path) -> int:
    """Run the tests marked ``cuda``; pytest's exit code. Their output goes to
    ``out/cuda_tests.log``; a failure's short summary is printed too."""
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-m", "cuda",
                           "-p", "no:cacheprovider", *(str(ROOT / f) for f in CUDA_TEST_FILES)],
                          capture_output=True, text=True, cwd=ROOT)
    (out / "cuda_tests.log").write_text(done.stdout + done.stderr)
    lines = done.stdout.strip().splitlines() or ["(no output)"]
    if done.returncode != 0:
        print("\n".join(line for line in lines if line.startswith(("FAILED", "ERROR", "E "))))
    print(f"CUDA tests: exit {done.returncode}, {lines[-1]}")
    return done.returncode


class GpuMonitor:
    """Samples the GPU's utilisation (%) and memory in use (MiB) with ``nvidia-smi`` while
    the arms run; :meth:`summary` is a line for the report."""

    def __init__(self) -> None:
        self.utilisation: list[float] = []
        self.memory: list[float] = []

    def sample(self) -> None:
        try:
            done = subprocess.run(["nvidia-smi", "--query-gpu=utilization.gpu,memory.used",
                                   "--format=csv,noheader,nounits"],
                                  capture_output=True, text=True, timeout=10)  # fmt: skip
            util, memory = done.stdout.splitlines()[0].split(",")
            self.utilisation.append(float(util))
            self.memory.append(float(memory))
        except (OSError, ValueError, IndexError, subprocess.SubprocessError):
            pass  # no nvidia-smi, or an answer it could not give: no sample

    def summary(self) -> str:
        if not self.utilisation:
            return "GPU utilisation: no samples (nvidia-smi did not answer)"
        util, memory = self.utilisation, self.memory
        return (f"GPU utilisation: mean {sum(util) / len(util):.0f}%, max {max(util):.0f}% "
                f"over {len(util)} samples; memory in use: max {max(memory):.0f} MiB")


def start_arm(device: str, args: argparse.Namespace, out: Path, jobs: int) -> subprocess.Popen:
    """Start ``abco bench`` on one device; its log goes to ``out/<device>.log``."""
    cmd = [sys.executable, "-m", "abco_train", "bench", "--track", "headline",
           "--tasks", args.tasks, "--methods", args.methods, "--seeds", str(args.seed),
           "--device", device, "--jobs", str(jobs), "--threads", "1", "--no-plots",
           "--out", str(out / device), *(TINY_OPTIONS if args.tiny else ())]
    with (out / f"{device}.log").open("w") as log:  # the child keeps its own handle
        return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)


def read_cells(grid: Path) -> dict[tuple[str, str], tuple[float, float | None]]:
    """(task, method) -> (wall seconds, headline score) of each finished cell of a grid."""
    if not (grid / RESULTS_FILE).is_file():  # the arm failed before its first cell
        return {}
    return {(row.get("task") or row["env"], row["method"]):
            (row["wall_s"], headline(row["final"]).get("score"))
            for row in read_results(grid).values() if row["status"] == "done"}


def fmt(value: float | None, decimals: int) -> str:
    """A figure in a 12-wide column, or '-' where there is none (a tiny run has no score)."""
    return f"{'-':>12}" if value is None else f"{value:12.{decimals}f}"


def report(out: Path, devices: list[str]) -> None:
    """Print and write the cells' wall times and scores per device, with the ratio."""
    grids = {device: read_cells(out / device) for device in devices}
    keys = sorted(set().union(*grids.values()))
    rows = []
    for task, method in keys:
        cpu = grids["cpu"].get((task, method), (None, None))
        gpu = grids.get("auto", {}).get((task, method), (None, None))
        ratio = cpu[0] / gpu[0] if cpu[0] and gpu[0] else None
        rows.append([task, method, cpu[0], gpu[0], ratio, cpu[1], gpu[1]])
    header = ["task", "method", "cpu s", "auto s", "x cpu/auto", "cpu score", "auto score"]
    print(f"{header[0]:<28}{header[1]:<18}" + "".join(f"{h:>12}" for h in header[2:]))
    for task, method, cpu_s, gpu_s, ratio, cpu_score, gpu_score in rows:
        print(f"{task:<28}{method:<18}{fmt(cpu_s, 1)}{fmt(gpu_s, 1)}"
              f"{fmt(ratio, 2)}{fmt(cpu_score, 3)}{fmt(gpu_score, 3)}")
    with (out / "gpu_times.csv").open("w", newline="") as f:
        csv.writer(f).writerows([header, *rows])


def main() -> int:
    """Run the check; exit 1 if the CUDA tests or an arm failed."""
    parser = argparse.ArgumentParser(description="The GPU check: CUDA tests, CUDA against CPU.")
    parser.add_argument("--out", type=Path, default=Path("runs/gpu-check"))
    parser.add_argument("--tasks", default=TASKS, help="headline tasks, comma-separated")
    parser.add_argument("--methods", default=METHODS, help="methods, comma-separated")
    parser.add_argument("--seed", type=int, default=100, help="a validation seed (default 100)")
    parser.add_argument("--cpu-jobs", type=int, default=4, help="CPU cells at a time")
    parser.add_argument("--cuda-jobs", type=int, default=4, help="auto-arm cells at a time")
    parser.add_argument("--arm-seconds", type=float, default=400,
                        help="stop both arms after this many seconds (default 400: with the "
                             "CUDA tests the check stays under 8 minutes)")
    parser.add_argument("--tiny", action="store_true", help="seconds: CartPole, two methods")
    args = parser.parse_args()
    from abco_train.bench.tasks import load_track

    track = load_track("headline")
    if (why := track.why_not_validation(args.seed)) is not None:  # timings spend no test seed
        print(f"error: seed {args.seed} is {why}; use a validation seed "
              f"({track.validation_seeds})", file=sys.stderr)
        return 2
    if args.tiny:
        args.tasks, args.methods = "cartpole-authors-data", "bc,bco"
    args.out.mkdir(parents=True, exist_ok=True)
    cuda = describe_device()
    failed = cuda_tests(args.out) != 0 if cuda else False
    if not cuda:
        print("CUDA tests: skipped, no CUDA device; the auto arm is skipped too")
    devices = ["cpu", "auto"] if cuda else ["cpu"]
    start = time.perf_counter()
    jobs = {"cpu": args.cpu_jobs, "auto": args.cuda_jobs}
    arms = {d: start_arm(d, args, args.out, jobs[d]) for d in devices}
    monitor = GpuMonitor()
    while any(arm.poll() is None for arm in arms.values()):
        if time.perf_counter() - start > args.arm_seconds:  # the check stays inside its minutes
            print(f"arms stopped at {args.arm_seconds:.0f} s: the cells not done are left out")
            for arm in arms.values():
                arm.terminate()
            break
        if cuda:
            monitor.sample()
        time.sleep(2)
    for device, arm in arms.items():
        code = arm.wait()
        print(f"{device} arm: exit {code} after {time.perf_counter() - start:.0f} s "
              f"(log: {args.out / device}.log)")
        failed |= code != 0
    report(args.out, devices)
    if cuda:
        print(monitor.summary())
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
