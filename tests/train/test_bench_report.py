"""``abco report`` on synthetic grids: run folders and ``results.jsonl`` written by hand.

A constructed grid over the six environments: ``iupe`` beats ``abco`` on every run of every
env, ``bc`` loses to it everywhere, a user's plugin ``knn-ifo`` ran CartPole only, ``ilpo`` and
``gaifo`` never ran, ``bc``'s runs predate the interaction counts, and a ``bco-alpha`` run was
stopped by its health check.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from abco_train.cli import main as abco_main
from abco_train.report import aggregates as aggregate
from abco_train.report import runs as report_grid
from abco_train.report.stats import iqm
from abco_train.report.write import GOALS, TABLE1_ENVS, table_evaluation, write_report

SEEDS = (0, 1, 2)


def _has_rliable() -> bool:
    return aggregate.load_rliable()[0] is not None


needs_rliable = pytest.mark.skipif(not _has_rliable(), reason="rliable is not importable here")


def fake_run(root: Path, env: str, method: str, seed: int, p: float | None,
             interactions: dict[str, int] | None = None, status: str = "ok"
             ) -> dict[str, Any]:  # fmt: skip
    """Write ``root/env/method/seed{seed}/final.json``; return its ``results.jsonl`` row."""
    run_dir = root / env / method / f"seed{seed}"
    run_dir.mkdir(parents=True)
    final: dict[str, Any] = {"env": env, "method": method, "seed": seed, "status": status}
    if status == "ok":
        assert p is not None
        score = {"performance": p, "aer": 10 * p, "success_rate": 1.0, "episodes": 2,
                 "episode_performance": [p - 0.01, p + 0.01],
                 "episode_returns": [10 * p - 0.1, 10 * p + 0.1]}  # fmt: skip
        final[table_evaluation(env)] = score
        if table_evaluation(env) != "episodes":
            final[table_evaluation(env, "test")] = dict(score)
    else:
        final["message"] = "the IDM is at chance"
    if interactions is not None:
        final["interactions"] = interactions
    (run_dir / "final.json").write_text(json.dumps(final))
    return {"env": env, "method": method, "seed": seed, "run_dir": str(run_dir),
            "status": "done" if status == "ok" else status, "final": final, "wall_s": 2.0,
            "reference": {"expert": 10.0, "random": 0.0}}  # fmt: skip


def counts(seed: int) -> dict[str, int]:
    return {"pre_demonstration": 1000, "post_demonstration": 500 + 10 * seed, "rl": 0,
            "remapping": 0}  # fmt: skip


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("synthetic") / "runs"
    rows = []
    for k, env in enumerate(TABLE1_ENVS):
        for seed in SEEDS:
            base = 0.5 + 0.05 * k + 0.01 * seed
            if env == "CartPole-v1":  # saturated: every method at P 1.0
                base = 1.0
            rows.append(fake_run(root, env, "abco", seed, base, counts(seed)))
            rows.append(fake_run(root, env, "iupe", seed, base + (0.0 if base == 1.0 else 0.31),
                                 counts(seed)))  # fmt: skip
            rows.append(fake_run(root, env, "bc", seed, base - (0.0 if base == 1.0 else 0.4)))
    for seed in SEEDS:
        rows.append(fake_run(root, "CartPole-v1", "knn-ifo", seed, 1.0,
                             {"pre_demonstration": 5000, "post_demonstration": 0, "rl": 0,
                              "remapping": 0}))  # fmt: skip
    rows.append(fake_run(root, "AbcoMaze10x10-v0", "bco-alpha", 0, None, counts(0),
                         status="idm_at_chance"))  # fmt: skip
    (root / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (root / "bench_log.jsonl").write_text(json.dumps(
        {"started": "x", "wall_s": 5 * 3600.0, "ran": len(rows), "skipped": 0, "failed": []}
    ) + "\n")  # fmt: skip
    return root


@pytest.fixture(scope="module")
def reported(synthetic: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("report")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(aggregate, "REPS", 200)
        files = write_report(synthetic, out)
    with files["csv"].open() as f:
        rows = list(csv.DictReader(f))
    return {"files": files, "md": files["report"].read_text(), "rows": rows, "out": out}


def _section(md: str, heading: str) -> str:
    part = md.split(heading, 1)[1]
    return part.split("\n## ", 1)[0]


def test_plugin_method_in_the_main_table(reported: dict[str, Any]) -> None:
    main = _section(reported["md"], "## Table 1 re-measured")
    cartpole = [line.split(" | ")[1] for line in main.splitlines()
                if line.startswith("| CartPole-v1 |")]  # fmt: skip
    assert cartpole == ["BC", "ABCO(α)", "IUPE", "knn-ifo"]  # built-ins first, then plugins
    assert "| AbcoMaze10x10-v0 | BCO(α) | 0 (+1 stopped) | missing |" in main  # counted
    # no row per missing cell: every row has a finished or a stopped run
    rows = [x.split(" | ") for x in main.splitlines() if x.startswith("| ")][2:]
    assert all(r[2] != "0" for r in rows) and not any(r[1] == "ILPO" for r in rows)


def test_missing_cells_are_summarised(reported: dict[str, Any]) -> None:
    part = _section(reported["md"], "## Missing, unfinished, failed or stopped cells")
    lines = [x for x in part.splitlines() if x.startswith("- ")]
    assert len(lines) <= 6, part
    # counted against what the grid ran: its 5 methods on its 6 envs, not Table 1's or 2's
    assert "33 of the grid's 90 cells have no finished run (each of its 5 methods on each of" \
           " its 6 environments" in part
    assert "- no finished run at all: bco-alpha (6 envs × seeds 0-2, 18 cells)" in lines
    assert not any("ilpo" in x or "abco-whole" in x for x in lines)
    assert "- knn-ifo: Acrobot-v1, MountainCar-v0, AbcoMaze3x3-v0, AbcoMaze5x5-v0," \
           " AbcoMaze10x10-v0 × seeds 0-2 (15 cells)" in lines
    assert any(x.startswith("- AbcoMaze10x10-v0 / bco-alpha: stopped, idm_at_chance on seed 0"
                            " (the IDM is at chance)") for x in lines)  # fmt: skip


def test_interaction_counts_in_report_and_csv(reported: dict[str, Any]) -> None:
    main = _section(reported["md"], "## Table 1 re-measured")
    assert "| Pre-demo | Post-demo | RL | Remap |" in main
    abco = next(x for x in main.splitlines() if x.startswith("| Acrobot-v1 | ABCO(α) |"))
    assert abco.endswith("| 1,000 | 510 | 0 | 0 |")  # mean per run: (500 + 510 + 520) / 3
    bc = next(x for x in main.splitlines() if x.startswith("| Acrobot-v1 | BC |"))
    assert bc.endswith("| – | – | – | – |")  # runs without counts (an old grid)
    rows = [r for r in reported["rows"] if r["table"] == "table1" and r["env"] == "Acrobot-v1"
            and r["method"] == "abco" and r["metric"].startswith("interactions/")]  # fmt: skip
    by_metric = {r["metric"]: r for r in rows}
    assert set(by_metric) == {"interactions/pre_demonstration",
                              "interactions/post_demonstration", "interactions/rl",
                              "interactions/remapping"}  # fmt: skip
    post = by_metric["interactions/post_demonstration"]
    assert post["evaluation"] == "training" and post["seeds"] == "3"
    assert float(post["mean"]) == pytest.approx(510.0)
    assert not any(r["method"] == "bc" and r["metric"].startswith("interactions/")
                   for r in reported["rows"])  # fmt: skip


def test_goals_and_separation(reported: dict[str, Any]) -> None:
    md = reported["md"]
    assert GOALS["wall_s"] == 4 * 3600.0
    assert "seven-method grid" not in md  # the grid lacks bco, ilpo, gaifo: not that grid
    goals = _section(md, "## Goals")
    iupe = next(x for x in goals.splitlines() if x.startswith("| CartPole-v1 | IUPE | 10.000 ["))
    assert iupe.endswith("| 500.000 | **short by 490.000** |")
    assert "| AbcoMaze10x10-v0 | IUPE | 10.700 [" in goals and goals.count("| IUPE |") == 6
    assert "| ILPO |" not in goals  # no row where it has no run; one line says so
    assert "- ILPO: no run on any environment in this grid." in goals
    assert "not decided" not in md and "issue" not in md
    sep = _section(md, "## Which environments separate methods")
    assert "Saturated: CartPole-v1." in sep
    assert "| CartPole-v1 | 4 | 1.000" in sep and "| 0.000 | no: all within 0.02 |" in sep


def test_score_matrices_handle_unequal_runs() -> None:
    envs = ("a", "b")
    scores = {"m": {"a": {0: 1.0, 1: 2.0, 2: 3.0}, "b": {2: 5.0, 0: 4.0}},
              "short": {"a": {0: 1.0}}}  # fmt: skip
    matrices, dropped, left_out = aggregate.score_matrices(scores, envs)
    np.testing.assert_array_equal(matrices["m"], [[1.0, 4.0], [2.0, 5.0]])  # lowest seeds
    assert dropped == {"m": 1} and left_out == {"short": ["b"]}


def test_probability_of_improvement_by_hand() -> None:
    x, y = np.array([[2.0, 1.0], [3.0, 1.0]]), np.array([[1.0, 1.0], [0.0, 1.0]])
    assert aggregate.probability_of_improvement(x, y) == pytest.approx((1.0 + 0.5) / 2)
    assert aggregate.probability_of_improvement(y, x) == pytest.approx((0.0 + 0.5) / 2)


@needs_rliable
def test_probability_of_improvement_is_rliables() -> None:
    from rliable import metrics

    rng = np.random.default_rng(3)
    for shape_x, shape_y in (((5, 6), (5, 6)), ((3, 4), (7, 4))):
        x = rng.integers(0, 4, shape_x).astype(float)  # many ties
        y = rng.integers(0, 4, shape_y).astype(float)
        assert aggregate.probability_of_improvement(x, y) == pytest.approx(
            metrics.probability_of_improvement(x, y))  # fmt: skip


@needs_rliable
def test_aggregates_of_a_constructed_grid(reported: dict[str, Any], synthetic: Path) -> None:
    part = _section(reported["md"], "## Aggregates: 6 of the 6 environments")
    assert "- left out: knn-ifo (no finished run on Acrobot-v1," in part
    assert "[Performance profiles" in part and "(performance_profile.png)" in part
    assert (reported["out"] / "performance_profile.png").stat().st_size > 0
    agg = {(r["method"], r["metric"]): r for r in reported["rows"] if r["table"] == "aggregate"}
    assert {m for m, _ in agg} == {"bc", "abco", "iupe"}
    iupe = [[1.0 if e == "CartPole-v1" else 0.81 + 0.05 * k + 0.01 * s
             for k, e in enumerate(TABLE1_ENVS)] for s in SEEDS]  # fmt: skip
    perf = agg[("iupe", "performance")]
    assert float(perf["iqm"]) == pytest.approx(iqm(np.ravel(iupe)))  # 18 runs: 4 cut per end
    assert float(perf["mean"]) == pytest.approx(np.mean(iupe))
    assert float(perf["iqm_ci_low"]) <= float(perf["iqm"]) <= float(perf["iqm_ci_high"])
    assert perf["seeds"] == "3" and perf["env"] == "all 6"
    # iupe beats every abco run on five envs and ties on CartPole: (5 * 1 + 0.5) / 6
    poi = {m: agg[(m, "probability_of_improvement_over_abco")] for m in ("bc", "iupe")}
    assert float(poi["iupe"]["mean"]) == pytest.approx(5.5 / 6)
    assert float(poi["bc"]["mean"]) == pytest.approx(0.5 / 6)
    for r in poi.values():
        assert 0.0 <= float(r["ci_low"]) <= float(r["mean"]) <= float(r["ci_high"]) <= 1.0
    assert "| IUPE | 0.917 [" in part and "| 3 / 3 |" in part
    assert float(agg[("iupe", "fraction_above_0.95")]["mean"]) == pytest.approx(
        np.mean(np.ravel(iupe) > 0.95))  # fmt: skip


@needs_rliable
def test_dominating_method_has_probability_one(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(aggregate, "REPS", 100)
    for k, env in enumerate(TABLE1_ENVS):
        for seed in (0, 1):
            fake_run(tmp_path, env, "abco", seed, 0.1 * k + 0.01 * seed)
            fake_run(tmp_path, env, "mine", seed, 2.0 + 0.1 * k + 0.01 * seed)
    files = write_report(tmp_path, tmp_path / "report", baseline="mine")
    md = files["report"].read_text()
    assert "### Probability of improvement over mine (baseline `mine`)" in md
    assert "| ABCO(α) | 0.000 [0.000, 0.000] | 2 / 2 |" in md
    files = write_report(tmp_path, tmp_path / "report")
    assert "| mine | 1.000 [1.000, 1.000] | 2 / 2 |" in files["report"].read_text()


def test_unknown_baseline_is_an_error(synthetic: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    assert abco_main(["report", str(synthetic), "--out", str(tmp_path), "--baseline",
                      "nope"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "unknown baseline 'nope'" in err
    assert "methods found: bc, bco-alpha, abco, iupe, knn-ifo" in err
    assert "Traceback" not in err and not (tmp_path / "report.md").exists()


def test_report_without_rliable(synthetic: Path, tmp_path: Path,
                                monkeypatch: pytest.MonkeyPatch) -> None:
    for name in [m for m in sys.modules if m == "rliable" or m.startswith("rliable.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "rliable", None)  # `import rliable` fails
    assert abco_main(["report", str(synthetic), "--out", str(tmp_path)]) == 0
    md = (tmp_path / "report.md").read_text()
    part = _section(md, "## Aggregates: 6 of the 6 environments")
    assert "Not computed: rliable is not installed" in part
    assert 'pip install "abco[stats]"' in part
    assert not (tmp_path / "performance_profile.png").exists()
    for heading in ("## Table 1 re-measured", "## Which environments separate methods",
                    "## Missing", "## Table 2"):  # fmt: skip
        assert heading in md
    with (tmp_path / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert rows and not any(r["table"] == "aggregate" for r in rows)


def _seven_methods(synthetic: Path, root: Path) -> None:
    """A copy of the synthetic grid with a run of every Table 1 method (the seven-method
    grid, whose wall-time goal the report judges)."""
    import shutil

    shutil.copytree(synthetic, root)
    rows = [fake_run(root, "CartPole-v1", m, 0, 1.0, counts(0)) for m in ("bco", "ilpo", "gaifo")]
    with (root / "results.jsonl").open("a") as f:
        f.write("".join(json.dumps(r) + "\n" for r in rows))


def test_a_users_grid_has_no_goal_of_the_project(tmp_path: Path) -> None:
    """Two envs, two seeds, two methods: counted against what ran; no seven-method goal."""
    root = tmp_path / "runs"
    rows = [fake_run(root, env, m, seed, 0.5 + 0.1 * seed, counts(seed))
            for env in ("CartPole-v1", "AbcoMaze5x5-v0") for m in ("bco", "abco")
            for seed in (0, 1)]  # fmt: skip
    flagged = rows[-1]  # a run a health check flagged: it ran to its end, it has a score
    flagged["final"]["health"] = {"idm_at_chance": [1, 2], "one_action_labels": []}
    (Path(flagged["run_dir"]) / "final.json").write_text(json.dumps(flagged["final"]))
    (root / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(aggregate, "REPS", 50)
        md = write_report(root, tmp_path / "out")["report"].read_text()
    checks = _section(md, "## Health checks")
    assert "- AbcoMaze5x5-v0 / abco: idm_at_chance on seed 1" in checks
    assert "issue" not in md and "not decided" not in md and "seven-method" not in md
    assert "## Aggregates: 2 of the 6 environments of Table 1" in md
    assert "None: every expected cell has every seed." in md


def test_partial_grid_under_the_wall_goal_is_not_met(synthetic: Path, tmp_path: Path) -> None:
    """A grid with cells still to run cannot have met the wall-time goal (only be over it)."""
    root = tmp_path / "runs"
    _seven_methods(synthetic, root)
    (root / "bench_log.jsonl").write_text(json.dumps(
        {"started": "x", "wall_s": 3600.0, "ran": 1, "skipped": 0, "failed": []}) + "\n")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(aggregate, "REPS", 50)
        md = write_report(root, tmp_path / "out")["report"].read_text()
    assert "Grid wall time so far 60.0 min" in md and "**not decided**" in md
    assert ": met." not in md.split("## Goals")[1].split("##")[0]


def test_reused_cells_count_in_the_wall_time(synthetic: Path, tmp_path: Path) -> None:
    """Cells copied in from another run folder (``reused_from``) ran in no logged session:
    their own time, over the sessions' jobs, is added before the goal is judged."""
    root = tmp_path / "runs"
    _seven_methods(synthetic, root)
    rows = [json.loads(x) for x in (root / "results.jsonl").read_text().splitlines()]
    rows[0].update(reused_from="/elsewhere", wall_s=7200.0)
    (root / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (root / "bench_log.jsonl").write_text("".join(json.dumps(x) + "\n" for x in (
        {"started": "x", "wall_s": 3.5 * 3600, "ran": 1, "skipped": 0, "failed": [], "jobs": 2},
        {"started": "y", "wall_s": 0.0, "ran": 1, "skipped": 0, "failed": [], "jobs": 2,
         "finished": False})))  # fmt: skip
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(aggregate, "REPS", 50)
        md = write_report(root, tmp_path / "out")["report"].read_text()
    assert "1 cell ran outside these sessions" in md and "3600.0 s at 2 job(s)" in md
    assert "Grid wall time 270.0 min" in md and "**over by 30.0 min**" in md
    assert md.count("stopped before its end") == 1
    # where the time goes: the env of the 7,200 s cell leads, with that cell's method first
    part = _section(md, "## Wall time")
    table = [x for x in part.splitlines() if x.startswith("| ") and "Cell time" not in x]
    assert table and table[0].startswith(f"| {rows[0]['env']} |")
    assert "7,2" in table[0].split("|")[3] and table[0].split("|")[5].strip().startswith(
        report_grid.LABELS.get(rows[0]["method"], rows[0]["method"]))
