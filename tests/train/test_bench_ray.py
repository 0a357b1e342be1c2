"""``abco bench --backend ray`` on a local Ray instance: same cell, same numbers as locally."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from test_bench_grid import comparable_final, comparable_metrics, tiny_overrides

from abco_train.bench import grid as bench

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def local_ray() -> Iterator[None]:
    """A local Ray instance for this module (the bench joins it and leaves it running)."""
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield
    ray.shutdown()


def test_ray_and_local_give_identical_results(local_ray: None, tmp_path: Path) -> None:
    overrides = tiny_overrides(tmp_path / "data")
    cells = bench.plan(["CartPole-v1"], ["abco"], [3])
    kwargs = {"overrides": overrides, "threads": 1, "quiet": True}
    by_ray = bench.run_grid(cells, tmp_path / "ray", backend="ray", **kwargs)
    assert ray.is_initialized()  # an existing instance is joined, not shut down
    by_process = bench.run_grid(cells, tmp_path / "local", backend="local", jobs=1, **kwargs)
    assert by_ray["ran"] == by_process["ran"] == 1
    assert by_ray["failed"] == by_process["failed"] == []
    ray_dir, local_dir = cells[0].run_dir(tmp_path / "ray"), cells[0].run_dir(tmp_path / "local")
    assert comparable_final(ray_dir) == comparable_final(local_dir)
    assert comparable_metrics(ray_dir) == comparable_metrics(local_dir)
    row = bench.read_results(tmp_path / "ray")[cells[0].key]
    assert row["backend"] == "ray" and row["status"] == "done"
    # a finished ray grid resumes (skips) like a local one
    again = bench.run_grid(cells, tmp_path / "ray", backend="ray", **kwargs)
    assert again["skipped"] == 1 and again["ran"] == 0


def test_failed_cell_is_reported_not_raised(local_ray: None, tmp_path: Path) -> None:
    overrides = {**tiny_overrides(tmp_path / "data"), "expert_data": str(tmp_path / "nope")}
    cells = bench.plan(["CartPole-v1"], ["bc"], [0])
    summary = bench.run_grid(cells, tmp_path / "runs", backend="ray", overrides=overrides,
                             threads=1, quiet=True)  # fmt: skip
    assert summary["failed"] == [cells[0].key]
    row = bench.read_results(tmp_path / "runs")[cells[0].key]
    assert row["status"] == "failed" and row["error"] and "Traceback" in row["traceback"]
