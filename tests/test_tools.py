"""``tools/attack.py``: its case table is well-formed, its judges tell the outcome classes
apart, and it runs end to end on two cheap cases (their verdicts are not asserted: they judge
abco, not this script)."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

attack = importlib.import_module("attack")  # tools/attack.py
core = importlib.import_module("attacks.core")


def result(rc: int | None, err: str = "", out: str = "") -> Any:
    return core.Result(["abco"], rc, out, err, 0.0, 60.0)


def test_the_case_table_is_well_formed() -> None:
    cases = attack.all_cases()
    keys = [(c.family, c.name) for c in cases]
    assert len(keys) == len(set(keys)), "two cases share a family and a name"
    assert {c.family for c in cases} == set(attack.FAMILIES)
    assert 150 <= len(cases) <= 400
    for family in attack.FAMILIES:
        mine = [c for c in cases if c.family == family]
        assert any(c.quick for c in mine), f"{family} has no case in --quick"
    assert all(callable(c.run) and c.name.strip() for c in cases)
    quick = attack.select(cases, quick=True, families=None, match=None)
    assert 0 < len(quick) < len(cases) / 4


@pytest.mark.parametrize(("res", "verdict"), [
    (result(2, "error: --lr must be a finite number, got nan\n"), core.PASS),
    (result(2, "usage: abco train [-h]\nabco train: error: argument --seed: invalid int\n"),
     core.PASS),
    (result(0, out="P 0.5\n"), "silent"),
    (result(None), "hang"),
    (result(1, 'Traceback (most recent call last):\n  File "x.py", line 1\nKeyError: \'env\'\n'),
     "traceback"),
    (result(1, "MemoryError\n"), "traceback"),
    (result(2, "error: one\nerror: two\n"), "traceback"),
    (result(2, "error: the problem\nwarning: said after it\n"), "traceback"),
    (result(-11, ""), "traceback"),
])  # fmt: skip
def test_refused_tells_the_classes_apart(res: Any, verdict: str) -> None:
    assert core.refused(res).verdict == verdict


def test_refused_can_require_a_word() -> None:
    res = result(2, "error: checkpoint.pt is damaged\n")
    assert core.refused(res, mention="convert-checkpoint").verdict == "traceback"
    res = result(2, "error: old checkpoint; run abco convert-checkpoint DIR\n")
    assert core.refused(res, mention="convert-checkpoint").verdict == core.PASS


def test_snapshot_sees_what_changed(tmp_path: Path) -> None:
    (tmp_path / "a.txt").write_text("a")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.txt").write_text("b")
    before = core.snapshot(tmp_path)
    (tmp_path / "new.txt").write_text("new files are fine")
    assert core.changed(before, tmp_path) == []
    (tmp_path / "sub" / "b.txt").write_text("B")
    (tmp_path / "a.txt").unlink()
    assert core.changed(before, tmp_path) == ["a.txt", "sub/b.txt"]
    assert core.kept(before, tmp_path, core.ok()).verdict == "lost"
    assert core.kind_of(tmp_path / "sub") == "dir" and core.kind_of(tmp_path / "x") == "missing"


def test_a_command_past_its_timeout_is_killed(tmp_path: Path) -> None:
    res = core.run_command([sys.executable, "-c", "import time; time.sleep(600)"],
                           env=core.base_env(tmp_path), timeout=1, memory=2**32)  # fmt: skip
    assert res.timed_out and core.refused(res).verdict == "hang"


def test_the_environment_keeps_caches_in_the_scratch_folder(tmp_path: Path) -> None:
    env = core.base_env(tmp_path)
    for key in ("ABCO_DATA_HOME", "HF_HOME"):
        assert env[key].startswith(str(tmp_path))
    assert env["HF_HUB_OFFLINE"] == "1"


def test_the_table_counts_each_class() -> None:
    case = core.Case("bounds", "x", lambda ctx: core.ok())
    rows = [(case, core.ok(), 0.0), (case, core.fail("hang", "slow"), 0.0),
            (case, core.skip("no mount"), 0.0)]  # fmt: skip
    text = attack.report(rows, 1.0)
    bounds = next(line.split() for line in text.splitlines() if line.startswith("bounds"))
    assert bounds[1:4] == ["3", "1", "1"]  # cases, passed, skipped
    assert bounds[4 + list(core.FAILURES).index("hang")] == "1"
    assert "bounds | x | hang: slow" in text


def test_the_script_runs_two_cheap_cases(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "attack.py"), "--families", "bounds", "-k",
         "generate --set layouts", "--out", str(tmp_path), "--jobs", "1"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stderr[-2000:]
    assert "family" in done.stdout and "\nbounds " in done.stdout
    results = json.loads((tmp_path / "attack_results.json").read_text())
    assert [r["case"] for r in results] == ["generate --set layouts=-1",
                                            "generate --set layouts=1000000"]
    assert {r["verdict"] for r in results} <= {core.PASS, core.SKIP, *core.FAILURES}
    assert done.returncode == (1 if any(r["verdict"] in core.FAILURES for r in results) else 0)


def test_unknown_families_are_refused() -> None:
    done = subprocess.run([sys.executable, str(ROOT / "tools" / "attack.py"), "--families",
                           "nosuch", "--list"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "unknown families nosuch" in done.stderr


def test_modern_diagnostics_reads_each_round_and_tabulates_the_last() -> None:
    """``tools/modern_diagnostics.py``: a metric is read from each round's ``train`` block,
    and the table gives the last round's mean over runs, its range and the probe's chance."""
    diagnostics = importlib.import_module("modern_diagnostics")
    from abco_train.report.runs import Run

    run = Run("cartpole-authors-data", "lapo", 100, ROOT, None)
    run._history = [{"iteration": 0, "train": {"probe_accuracy": 0.5}},
                    {"iteration": 1, "train": {"other": 1.0}},
                    {"iteration": 2, "train": {"probe_accuracy": 0.9}}]  # fmt: skip
    assert diagnostics.per_round(run, "probe_accuracy") == [0.5, 0.9]
    found = {"lapo": {"cartpole-authors-data": [[0.5, 0.9], [0.7]]}}
    text = diagnostics.table(found, {"cartpole-authors-data": "CartPole-v1"})
    assert "| lapo | probe_accuracy | cartpole-authors-data | 2 | 0.800 | 0.700-0.900 | 0.50 |" \
        in text


def test_seed_precision_predicts_the_width_by_hand(tmp_path: Path) -> None:
    """``tools/seed_precision.py``: scores floored at 0 and runs without one left out, as in
    the report; the normal width is ``2 * 1.96 * sqrt(sum_t var_t / n_t) / tasks``; the
    bootstrap's intervals of a task with one value repeated have no width."""
    precision = importlib.import_module("seed_precision")
    rows = [{"method": "bco", "task": task, "final": {"headline": "episodes",
             "episodes": {"score": score}}} for task, score in
            (("a", -0.5), ("a", 1.0), ("b", 0.5), ("b", 0.5), ("b", 0.0))]  # fmt: skip
    rows.append({"method": "bco", "task": "b", "final": None})  # failed: left out
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    by_task = precision.scores(tmp_path / "results.jsonl")["bco"]
    assert by_task == {"a": [0.0, 1.0], "b": [0.5, 0.5, 0.0]}
    expected = 2 * 1.96 * (0.5 / 2 + (1 / 12) / 3) ** 0.5 / 2  # var_a 0.5, var_b 1/12
    assert abs(precision.normal_width(by_task, {"a": 2, "b": 3}) - expected) < 1e-12
    rng = np.random.default_rng(0)
    assert precision.bootstrap_widths({"a": [0.3, 0.3]}, {"a": 5}, 2, rng) == (0.0, 0.0)
    assert precision.main([str(tmp_path / "nowhere")]) == 2
