"""``abco bench`` on a tiny CartPole grid (local processes) and ``abco report`` from it."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest

import abco_data
from abco_train.bench import grid as bench
from abco_train.cli import main as abco_main
from abco_train.methods.base import INTERACTION_KINDS
from abco_train.report import published as paper

TINY_TRAINING = {"iterations": 1, "idm_epochs": 1, "policy_epochs": 1, "eval_episodes": 3}


def tiny_overrides(directory: Path) -> dict[str, Any]:
    """Trainer overrides of a seconds-long CartPole cell on tiny generated datasets."""
    directory.mkdir(parents=True, exist_ok=True)
    expert = abco_data.generate("abco/cartpole-expert-v0", directory / "expert.hdf5",
                                progress=False, episodes=2, reference_episodes=3,
                                reference_expert_episodes=2)  # fmt: skip
    pre = abco_data.generate("abco/cartpole-pre-v0", directory / "pre.hdf5", progress=False,
                             transitions=500, reference_episodes=3,
                             reference_expert_episodes=2)  # fmt: skip
    return {"expert_data": str(expert), "pre_data": str(pre), **TINY_TRAINING}


def comparable_final(run_dir: Path) -> dict[str, Any]:
    """``final.json`` without what legitimately differs between hosts (paths, timings)."""
    final = json.loads((run_dir / "final.json").read_text())
    return {k: v for k, v in final.items() if k not in ("figures", "seconds")}


def comparable_metrics(run_dir: Path) -> list[dict[str, Any]]:
    """``metrics.jsonl`` without the timings."""
    lines = (run_dir / "metrics.jsonl").read_text().splitlines()
    return [{k: v for k, v in json.loads(x).items() if not k.startswith("seconds")}
            for x in lines]  # fmt: skip


CELLS = bench.plan(["CartPole-v1"], ["bco-alpha", "abco"], [0, 1])


@pytest.fixture(scope="module")
def grid(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The tiny grid, run once; one cell was interrupted beforehand (checkpoint, no final)."""
    from abco_train.config.run import RunConfig
    from abco_train.harness.loop import train

    root = tmp_path_factory.mktemp("bench")
    overrides = tiny_overrides(root / "data")
    out = root / "runs"
    interrupted = bench.cell_config(CELLS[-1], out, overrides, threads=1)
    assert train(RunConfig(**interrupted), stop_after=1) is None
    summary = bench.run_grid(CELLS, out, overrides=overrides, jobs=2, threads=1, quiet=True)
    return {"out": out, "overrides": overrides, "summary": summary}


def test_parse_seeds_and_lists() -> None:
    assert bench.parse_seeds("0-4") == [0, 1, 2, 3, 4]
    assert bench.parse_seeds("3, 1-2,3") == [3, 1, 2]
    assert bench.parse_list("a, b,,a") == ["a", "b"]
    for bad in ("x", "4-2", ""):
        with pytest.raises(ValueError):
            bench.parse_seeds(bad)


def test_cell_config_rejects_per_cell_overrides() -> None:
    with pytest.raises(ValueError, match="seed"):
        bench.cell_config(CELLS[0], "out", {"seed": 3})


def test_grid_runs_every_cell(grid: dict[str, Any]) -> None:
    out, summary = grid["out"], grid["summary"]
    assert summary["ran"] == 4 and summary["skipped"] == 0 and summary["failed"] == []
    rows = bench.read_results(out)
    assert sorted(rows) == sorted(c.key for c in CELLS)
    for cell in CELLS:
        row = rows[cell.key]
        assert row["status"] == "done" and row["wall_s"] > 0
        assert row["final"]["episodes"]["episodes"] == 3
        assert row["reference"]["expert"] > row["reference"]["random"]
        assert (cell.run_dir(out) / "final.json").exists()
        assert json.loads((cell.run_dir(out) / "config.json").read_text())["threads"] == 1
    # the interrupted cell resumed after its first iteration: both iterations logged once
    its = [r["iteration"] for r in comparable_metrics(CELLS[-1].run_dir(out))]
    assert its == [0, 1]
    log = [json.loads(x) for x in (out / bench.BENCH_LOG).read_text().splitlines()]
    assert log[-1]["ran"] == 4 and log[-1]["wall_s"] > 0


def test_rerun_skips_finished_cells(grid: dict[str, Any]) -> None:
    out = grid["out"]
    before = bench.read_results(out)
    mtimes = {c.key: (c.run_dir(out) / "final.json").stat().st_mtime_ns for c in CELLS}
    code = abco_main(["bench",
        "--envs", "CartPole-v1", "--methods", "bco-alpha,abco", "--seeds", "0-1", "--out",
        str(out), "--quiet", "--threads", "1",
        *[f"--{k.replace('_', '-')}={v}" for k, v in grid["overrides"].items()],
    ])  # fmt: skip
    assert code == 0
    log = [json.loads(x) for x in (out / bench.BENCH_LOG).read_text().splitlines()]
    assert log[-1]["skipped"] == 4 and log[-1]["ran"] == 0
    assert bench.read_results(out) == before
    assert mtimes == {c.key: (c.run_dir(out) / "final.json").stat().st_mtime_ns for c in CELLS}


def test_finished_cell_of_another_config_is_refused(grid: dict[str, Any]) -> None:
    changed = {**grid["overrides"], "idm_epochs": 2}  # a method option is the cell's too
    with pytest.raises(ValueError, match="another config"):
        bench.run_grid(CELLS, grid["out"], overrides=changed, threads=1, quiet=True)


def test_unknown_method_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown method"):
        bench.run_grid(bench.plan(["CartPole-v1"], ["nope"], [0]), tmp_path, quiet=True)


def test_report_from_grid(grid: dict[str, Any], tmp_path: Path) -> None:
    assert abco_main(["report", str(grid["out"]), "--out", str(tmp_path), "--labels-env",
                        "CartPole-v1"]) == 0  # fmt: skip
    md = (tmp_path / "report.md").read_text()
    for heading in ("## Table 1 re-measured", "## Table 1, mazes on the held-out test split",
                    "## Table 2: ablation", "## Goals", "## Reference returns",
                    "## Wall time", "## Missing, unfinished, failed or stopped cells",
                    "## Aggregates: 1 of the 6 environments of Table 1",
                    "## Which environments separate methods"):  # fmt: skip
        assert heading in md
    # counted against the grid's own cells (CartPole, two methods, two seeds): none missing
    assert "None: every expected cell has every seed." in md
    assert "short by" in md  # a tiny budget falls short of the paper's CartPole
    aggregates = md.split("## Aggregates: 1 of the 6", 1)[1].split("\n## ", 1)[0]
    assert "| BCO(α) | 2 |" in aggregates and "| ABCO(α) | 2 |" in aggregates
    # the runs' interaction counts, beside P and AER
    for method in ("BCO(α)", "ABCO(α)"):
        row = next(x for x in md.splitlines() if x.startswith(f"| CartPole-v1 | {method} |"))
        pre, post, rl, remap = row.strip("| ").split(" | ")[-4:]
        assert int(pre.replace(",", "")) > 0 and int(post.replace(",", "")) > 0
        assert (rl, remap) == ("0", "0")
    assert (tmp_path / "performance_per_iteration.png").stat().st_size > 0
    assert (tmp_path / "idm_label_distribution.png").stat().st_size > 0
    with (tmp_path / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    measured = [r for r in rows if r["table"] == "table1" and r["seeds"] != "0"
                and not r["metric"].startswith("interactions/")]
    assert {(r["method"], r["metric"]) for r in measured} == {
        ("bco-alpha", "performance"), ("bco-alpha", "aer"), ("abco", "performance"),
        ("abco", "aer")}  # fmt: skip
    finals = {c.key: json.loads((c.run_dir(grid["out"]) / "final.json").read_text())
              for c in CELLS}  # fmt: skip
    for r in measured:
        assert r["seeds"] == "2" and r["evaluation"] == "episodes"
        lo, mean, hi = float(r["ci_low"]), float(r["mean"]), float(r["ci_high"])
        assert lo <= mean <= hi
        per_seed = [f["episodes"][r["metric"]] for k, f in finals.items() if r["method"] in
                    k.split("/")[1:2]]  # fmt: skip
        assert mean == pytest.approx(sum(per_seed) / len(per_seed))
        assert float(r["paper"]) == paper.PAPER_TABLE1[r["method"]]["CartPole-v1"][
            0 if r["metric"] == "performance" else 1]
    # the CSV's numbers are the Markdown's
    counted = {(r["method"], r["metric"]) for r in rows if r["table"] == "table1"
               and r["metric"].startswith("interactions/")}  # fmt: skip
    assert counted == {(m, f"interactions/{k}") for m in ("bco-alpha", "abco")
                       for k in INTERACTION_KINDS}  # fmt: skip
    abco_p = next(r for r in measured if r["method"] == "abco" and r["metric"] == "performance")
    assert f"{float(abco_p['mean']):.3f} [{float(abco_p['ci_low']):.3f}," in md


def test_results_rebuilt_from_run_folders(grid: dict[str, Any]) -> None:
    """Cells finished outside ``abco bench`` (or a lost results.jsonl) are collected too."""
    out = grid["out"]
    (out / bench.RESULTS_FILE).unlink()
    summary = bench.run_grid(CELLS, out, overrides=grid["overrides"], threads=1, quiet=True)
    assert summary["skipped"] == 4 and summary["ran"] == 0
    rows = bench.read_results(out)
    assert sorted(rows) == sorted(c.key for c in CELLS)
    for cell in CELLS:
        row = rows[cell.key]
        assert row["status"] == "done" and row["wall_s"] is None
        assert row["final"] == json.loads((cell.run_dir(out) / "final.json").read_text())
        assert row["reference"]["expert"] == 500.0


def test_a_killed_session_leaves_its_time(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                          ) -> None:  # fmt: skip
    """The session's log line is written before the first cell and after every cell, so a
    grid stopped mid-way keeps its time up to its last finished cell (and the earlier lines)."""
    out = tmp_path / "runs"
    out.mkdir()
    earlier = {"started": "earlier", "wall_s": 1.0, "ran": 1, "skipped": 0, "failed": []}
    (out / bench.BENCH_LOG).write_text(json.dumps(earlier) + "\n")

    def one_cell_then_killed(work: Any, tasks: list[dict[str, Any]], plugins: Any, jobs: int
                             ) -> Any:  # fmt: skip
        yield 0, work(tasks[0], tuple(plugins))
        raise KeyboardInterrupt

    monkeypatch.setattr(bench.backends, "run_local", one_cell_then_killed)
    with pytest.raises(KeyboardInterrupt):
        bench.run_grid(CELLS[:2], out, overrides=tiny_overrides(tmp_path / "data"), jobs=1,
                       threads=1, quiet=True)  # fmt: skip
    log = [json.loads(x) for x in (out / bench.BENCH_LOG).read_text().splitlines()]
    assert len(log) == 2 and log[0] == earlier
    assert log[1]["finished"] is False and log[1]["ran"] == 1 and log[1]["wall_s"] > 0
    assert bench.read_results(out)[CELLS[0].key]["status"] == "done"
