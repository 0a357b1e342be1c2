"""Every script in ``benchmarks/`` runs end to end at its ``--tiny`` size (no timing asserted).

The scripts are not imported by the package, so nothing else would notice an API change that
breaks them. Each runs in a subprocess with this checkout first on ``PYTHONPATH``; the test
checks the exit code and the table the script prints, never a figure.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: script -> strings its ``--tiny`` output must hold (table headers and row labels).
EXPECTED = {
    "bench_envs.py": ["Minigrid-Empty-8x8", "single steps/s", "vector frames/s", "x Minigrid",
                      "AbcoMaze10x10-v0    224x224"],
    "bench_data.py": ["operation", "abco", "minari lossless", "minari jpeg", "x lossless",
                      "x jpeg", "write (collect + create)", "read every transition",
                      "sample 100 transitions", "jpeg_encoding=False",
                      "abco read back the recorded frames bit for bit: yes", "goals:"],
    "bench_load.py": ["idle s", "loaded s", "ratio", "CartPole-v1"],
    "bench_phases.py": ["wall s", "data", "pairs", "idm", "policy", "rollouts", "evaluation",
                        "references", "records", "cartpole-authors-data       bco",
                        "share of the wall time"],
    "bench_gpu.py": ["CUDA device:", "cpu arm: exit 0", "x cpu/auto",
                     "cartpole-authors-data       bc"],
    "bench_vector_update.py": ["transposed ms", "last-dim ms", "ratio", "medians of"],
    "bench_pair_inputs.py": ["built once ms", "per pass ms", "ratio", "medians of"],
    "bench_train.py": ["env", "method", "result", "AbcoMaze3x3-v0     abco       P=",
                       "CartPole-v1        abco       P="],
}


def test_every_benchmark_is_covered():
    assert sorted(p.name for p in (ROOT / "benchmarks").glob("bench_*.py")) == sorted(EXPECTED)


@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_benchmark_runs_tiny(script, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]),
        "MINARI_DATASETS_PATH": str(tmp_path / "minari"), "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--tiny"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{script} exited {done.returncode}:\n{done.stderr[-3000:]}"
    lines = done.stdout.splitlines()
    missing = [s for s in EXPECTED[script] if s not in done.stdout]
    assert not missing, f"{script} printed no {missing}:\n" + "\n".join(lines[-30:])


def test_bench_gpu_runs_every_cuda_test():
    """bench_gpu.py runs the tests marked ``cuda`` in the files it names: every such file."""
    import re

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from bench_gpu import CUDA_TEST_FILES
    finally:
        sys.path.pop(0)
    marked = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").rglob("test_*.py")
                    if re.search(r"pytest\.mark\.cuda\b", p.read_text()))
    assert marked == sorted(CUDA_TEST_FILES)


@pytest.mark.parametrize(("seed", "message"), [
    ("2000", "is a test seed"),  # the track's
    ("2019", "is a test seed"),  # the classic tasks' only: the mazes test 2000-2009
    ("1000", "is not a validation seed"),  # the v1 grid's
])
def test_bench_phases_refuses_a_seed_outside_validation(tmp_path, seed, message):
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_phases.py"),
                           "--seed", seed, "--out", str(tmp_path)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})  # fmt: skip
    assert done.returncode == 2 and message in done.stderr
