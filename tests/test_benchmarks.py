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
    "bench_gpu.py": ["CUDA device:", "cpu arm: exit 0", "x cpu/cuda",
                     "cartpole-authors-data       bc"],
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
