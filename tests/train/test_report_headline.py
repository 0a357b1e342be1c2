"""``abco report`` on a benchmark track: synthetic run folders of records that carry a task.

Three tasks, seeds 0-2, every method: ``abco`` and ``iupe`` score the same (undecided on three
seeds: the interval of P leaves [0.40, 0.60]), every other IfO method lies strictly between or
below (one better); ``bc`` beats them all on true actions
(a reference, kept out of the aggregates); ``random`` did not run on one task; ``bc``'s
records on the maze task and one ``bco`` record predate the score; ``ilpo``'s records carry no
code version and one ``abco`` record another one; a record without a task (the paper track)
sits beside them.
"""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest

from abco_train.bench.records import RecordError, check_final
from abco_train.harness import runtime
from abco_train.report import aggregates, provenance, ranking
from abco_train.report.headline import IFO_METHODS, headline_value
from abco_train.report.ranking import standings, verdict
from abco_train.report.write import write_report

TASKS = {"acrobot-budget": ("Acrobot-v1", "episodes"),
         "cartpole-short": ("CartPole-v1", "episodes"),
         "maze5-heldout": ("AbcoMaze5x5-v0", "test/paper")}  # fmt: skip
#: Each method's score on every task (seed s adds 0.01 s).
BASE = {"bco": 0.2, "bco-alpha": 0.5, "bco-alpha-torabi": 0.45, "abco": 0.8, "iupe": 0.8,
        "ilpo": 0.3, "gaifo": 0.1, "bc": 0.95, "expert": 1.0, "random": 0.0}  # fmt: skip
THIS = {"version": "1.0", "source": "cafe"}
OTHER = {"version": "0.9", "source": "beef"}
SEEDS = (0, 1, 2)


def _block(score: float, with_score: bool = True) -> dict[str, Any]:
    block: dict[str, Any] = {"performance": score - 0.05, "aer": 10 * score,
                             "success_rate": 0.5, "episodes": 2}  # fmt: skip
    if with_score:
        block |= {"score": score, "episode_scores": [score - 0.01, score + 0.01]}
    return block


def task_record(task: str, method: str, seed: int, extra: dict[str, Any] | None = None
                ) -> dict[str, Any]:  # fmt: skip
    """The ``final.json`` of a benchmark-track run (``extra`` replaces keys)."""
    env, head = TASKS[task]
    score = BASE[method] + 0.01 * seed
    older = (method, task) == ("bc", "maze5-heldout") or (method, task, seed) == (
        "bco", "cartpole-short", 2)
    version = None if method == "ilpo" else (
        OTHER if (method, task, seed) == ("abco", "maze5-heldout", 2) else THIS)
    final = {"env": env, "method": method, "seed": seed, "status": "ok", "task": task,
             "budget": 5000, "headline": head, head: _block(score, not older),
             "interactions": {"pre_demonstration": 1000 + 100 * seed, "rl": 0},
             "seconds": 60.0 + seed, "code_version": version}  # fmt: skip
    return {k: v for k, v in {**final, **(extra or {})}.items() if v is not None}


def write_track(root: Path, tasks: Iterable[str] = TASKS, methods: Iterable[str] = BASE
                ) -> Path:  # fmt: skip
    """Run folders of ``tasks`` x ``methods`` x seeds 0-2 (no ``random`` on acrobot-budget)."""
    for task in tasks:
        for method in methods:
            if (task, method) == ("acrobot-budget", "random"):
                continue
            for seed in SEEDS:
                run_dir = root / task / method / f"seed{seed}"
                run_dir.mkdir(parents=True)
                (run_dir / "final.json").write_text(json.dumps(task_record(task, method, seed)))
                (run_dir / "config.json").write_text(json.dumps({"task": task, "preset": "cpu"}))
    return root


@pytest.fixture(scope="module")
def track(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = write_track(tmp_path_factory.mktemp("track") / "runs")
    paper = root / "CartPole-v1" / "abco" / "seed0"  # a record without a task
    paper.mkdir(parents=True)
    (paper / "final.json").write_text(json.dumps(
        {"env": "CartPole-v1", "method": "abco", "seed": 0, "status": "ok", "seconds": 30.0,
         "episodes": {"performance": 1.0, "aer": 500.0, "success_rate": 1.0, "episodes": 1}}))
    unfinished = root / "cartpole-short" / "knn-ifo" / "seed0"  # no record: its folder's task
    unfinished.mkdir(parents=True)
    return root


def _report(root: Path, out: Path, version: dict[str, str] | None) -> dict[str, Any]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(aggregates, "REPS", 200)
        if version is None:
            mp.delattr(runtime, "code_version", raising=False)
        else:
            mp.setattr(runtime, "code_version", lambda: dict(version), raising=False)
        files = write_report(root, out)
    with files["csv"].open() as f:
        rows = list(csv.DictReader(f))
    return {"files": files, "md": files["report"].read_text(), "rows": rows}


@pytest.fixture(scope="module")
def reported(track: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return _report(track, tmp_path_factory.mktemp("report"), THIS)


def _section(md: str, heading: str) -> str:
    return md.split(heading, 1)[1].split("\n## ", 1)[0]


def _table(md: str, task: str) -> dict[str, list[str]]:
    """A task table's rows by method label."""
    part = md.split(f"### {task}\n", 1)[1].split("\n### ", 1)[0].split("\n## ", 1)[0]
    rows = [x.split(" | ") for x in part.splitlines() if x.startswith("| ")][1:]
    return {r[1]: r for r in rows}


def test_headline_first_grouped_by_task(reported: dict[str, Any]) -> None:
    md = reported["md"]
    order = ["## Summary", "## Code versions", "## Headline", "### acrobot-budget",
             "### cartpole-short", "### maze5-heldout", "## Aggregates over the 3 task(s)",
             "## Pairwise", "## The paper track", "## Table 1 re-measured", "## Wall time"]
    assert [md.index(h) for h in order] == sorted(md.index(h) for h in order)
    rows = _table(md, "acrobot-budget")
    ranked = [label for label, r in rows.items() if r[0] != "| –"]
    assert ranked[:2] == ["ABCO(α)", "IUPE"] and ranked[-1] == "GAIfO" and len(ranked) == 7
    abco = rows["ABCO(α)"]
    assert abco[2:5] == ["IfO", "3", "0.810 [0.800, 0.820]"]  # seeds only: [0.80, 0.82]
    assert abco[5:7] == ["0.50", "1,100 / 5,000 (22%)"]
    assert "abco's variant of ILPO" in rows["ILPO (abco's variant)"][7]


def test_reference_rows_in_every_task(reported: dict[str, Any]) -> None:
    for task in TASKS:
        rows = _table(reported["md"], task)
        assert {"Expert", "Random"} <= set(rows)
        assert rows["Expert"][2] == "reference" and rows["Expert"][0] == "| –"
    assert _table(reported["md"], "acrobot-budget")["Random"][3:5] == ["0", "not run"]
    assert _table(reported["md"], "cartpole-short")["Random"][4] == "0.010 [0.000, 0.020]"


def test_bc_is_a_labelled_reference_outside_the_aggregates(reported: dict[str, Any]) -> None:
    bc = _table(reported["md"], "cartpole-short")["BC"]
    assert bc[0] == "| –" and bc[2] == "true actions" and "outside the IfO aggregates" in bc[7]
    aggregate = _section(reported["md"], "## Aggregates over the 3 task(s)")
    pairwise = _section(reported["md"], "## Pairwise")
    assert "| BC |" not in aggregate and "BC" not in pairwise.replace("BCO", "")
    assert "Expert" not in aggregate + pairwise and "knn-ifo" not in aggregate + pairwise
    rows = [r for r in reported["rows"] if r["table"] in ("headline-aggregate", "pairwise")]
    # the grid ran the seven classic IfO methods; the two modern ones have no runs in it
    assert {r["method"] for r in rows} == set(IFO_METHODS) - {"dilo", "lapo"}
    assert [r["method"] for r in reported["rows"]
            if r["table"] == "headline" and r["metric"] == "score"].count("bc") == 2


def test_aggregates_rank_the_ifo_methods(reported: dict[str, Any]) -> None:
    part = _section(reported["md"], "## Aggregates over the 3 task(s)")
    lines = [x for x in part.splitlines() if x.startswith("| ") and x[2].isdigit()]
    assert [x.split(" | ")[1] for x in lines] == [
        "ABCO(α)", "IUPE", "BCO(α)", "BCO(α), Torabi", "ILPO (abco's variant)", "BCO", "GAIfO"]
    assert "- left out: 1 finished run(s) without a score (older records)" in part
    gap = next(r for r in reported["rows"] if r["table"] == "headline-aggregate"
               and r["method"] == "gaifo" and r["metric"] == "optimality_gap")  # fmt: skip
    assert float(gap["mean"]) == pytest.approx(0.89)  # 1 - 0.11: the mean of max(1 - x, 0)
    for name in ("headline_profile", "headline_aggregates", "headline_tasks"):
        png = reported["files"][name]
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"]({png.name})" in reported["md"]


def test_pairwise_verdicts(reported: dict[str, Any]) -> None:
    part = _section(reported["md"], "## Pairwise")
    rows = [x.split(" | ") for x in part.splitlines() if x.startswith("| ")][1:]
    assert len(rows) == 21
    verdicts = {(r[0][2:], r[1]): r[3].rstrip(" |") for r in rows}
    # the same scores, but three seeds a task: P's interval is wider than the equivalence band
    assert verdicts[("ABCO(α)", "IUPE")] == "undecided"
    assert verdicts[("BCO", "ABCO(α)")] == "better: ABCO(α)"
    assert verdicts[("BCO", "GAIfO")] == "better: BCO"
    assert "- ABCO(α) (`abco`): ahead of `bco` 1.00, `bco-alpha` 1.00" in part
    assert " `iupe` 0.50." in part
    assert sum(r["table"] == "pairwise" for r in reported["rows"]) == 21


@pytest.mark.parametrize(("low", "high", "expected"), [
    (0.62, 0.91, "better"),  # a clear win of X
    (0.02, 0.31, "worse"),  # a clear win of Y
    (0.35, 0.66, "undecided"),  # reaches 0.5, leaves the band
    (0.5, 0.8, "undecided"),  # touching 0.5 from above
    (0.2, 0.5, "undecided"),  # touching 0.5 from below
    (0.5, 0.5, "equivalent"),  # every run tied
    (0.41, 0.59, "equivalent"),  # inside [0.40, 0.60]
    (0.40, 0.60, "equivalent"),  # the band's edges count
    (0.52, 0.58, "better"),  # inside the band, but above 0.5: ahead by a little
])  # fmt: skip
def test_verdict(low: float, high: float, expected: str) -> None:
    assert verdict(low, high) == expected


def test_standings_name_who_is_ahead() -> None:
    table = standings({("bco", "abco"): (0.25, 0.1, 0.4), ("bco", "iupe"): (0.5, 0.5, 0.7),
                       ("abco", "iupe"): (0.5, 0.45, 0.55)})  # fmt: skip
    assert table["abco"] == ([("bco", 0.75)], [], [("iupe", 0.5)], [])
    assert table["bco"] == ([], [("abco", 0.25)], [], [("iupe", 0.5)])
    assert table["iupe"] == ([], [], [("abco", 0.5)], [("bco", 0.5)])


def test_scores_below_random_enter_the_aggregates_at_the_floor() -> None:
    """A run far below random (LunarLander's unbounded returns) counts as a random one: the
    mean and the pair are those of the floored scores, and the lift is counted per task."""
    rl = aggregates.load_rliable()[0]
    if rl is None:
        pytest.skip("rliable is not installed")
    scores = {"bco": {"a": {0: -3.0, 1: 0.5}, "b": {0: 1.0, 1: 1.0}},
              "abco": {"a": {0: -0.1, 1: 0.5}, "b": {0: 1.0, 1: 1.0}}}
    ranked = ranking.compute(scores, ["a", "b"], rl, reps=50)
    assert ranked.mean["bco"][0] == pytest.approx(0.625)  # (0 + 0.5 + 1 + 1) / 4, not -0.125
    assert ranked.floored == {"bco": {"a": 1}, "abco": {"a": 1}}
    assert ranked.pairs[("bco", "abco")][0] == pytest.approx(0.5)  # both at 0: a tie, not a loss


def test_other_code_versions_are_flagged(reported: dict[str, Any]) -> None:
    part = _section(reported["md"], "## Code versions")
    assert "This code: abco 1.0, source cafe." in part
    assert ("88 record(s): 77 made by this code, 1 by another version (abco 0.9 source beef),"
            " 10 without a code version (older records)") in part  # fmt: skip
    assert "| maze5-heldout | abco | 3 | 2 | 1 | 0 |" in part
    assert "| cartpole-short | ilpo | 3 | 0 | 0 | 3 |" in part
    assert "| CartPole-v1 | abco | 1 | 0 | 0 | 1 |" in part  # the paper track's record
    assert "| acrobot-budget | abco |" not in part  # nothing to flag there
    maze = _table(reported["md"], "maze5-heldout")
    assert "1 record(s) made by another code version" in maze["ABCO(α)"][7]
    assert "3 record(s) without a code version" in maze["ILPO (abco's variant)"][7]


def test_without_the_current_code_version_or_rliable(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    root = write_track(tmp_path / "runs", ["maze5-heldout"], ["abco", "ilpo", "random"])
    for name in [m for m in sys.modules if m == "rliable" or m.startswith("rliable.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "rliable", None)  # `import rliable` fails
    reported = _report(root, tmp_path / "out", None)
    part = _section(reported["md"], "## Code versions")
    assert "The current code's version is unknown" in part and "| Not comparable |" in part
    assert "9 record(s): 0 made by this code, 0 by another version, 3 without a code version" \
           " (older records), 6 not comparable" in part  # fmt: skip
    assert "| maze5-heldout | abco | 3 | 0 | 0 | 0 | 3 |" in part
    for heading in ("## Aggregates over the 1 task(s)", "## Pairwise"):
        assert "Not computed: rliable is not installed" in _section(reported["md"], heading)
    assert _table(reported["md"], "maze5-heldout")["ABCO(α)"][4] == "0.810 [0.800, 0.820]"
    assert "headline_profile" not in reported["files"]
    assert "headline_aggregates" not in reported["files"]
    assert reported["files"]["headline_tasks"].stat().st_size > 0  # drawn without rliable
    assert {r["table"] for r in reported["rows"]} == {"headline"}


def test_older_records_without_score(reported: dict[str, Any]) -> None:
    bc = _table(reported["md"], "maze5-heldout")["BC"]
    assert bc[4] == "0.910 [0.900, 0.920] (P)"  # the paper's P: score 0.96 - 0.05
    assert "no score: older record (the paper's P)" in bc[7]
    bco = _table(reported["md"], "cartpole-short")["BCO"]
    assert bco[3] == "2" and "1 older record(s) without a score left out" in bco[7]
    bc_row = next(r for r in reported["rows"] if r["table"] == "headline"
                  and r["env"] == "maze5-heldout" and r["method"] == "bc")  # fmt: skip
    assert bc_row["metric"] == "performance"


def test_training_time(reported: dict[str, Any]) -> None:
    part = _section(reported["md"], "## Wall time")
    total = 29 * 3 * 60.0 + 29 * 3.0 + 30.0  # 29 task cells of seeds 0-2, the paper's record
    assert f"Training wall time summed over the runs: {total:,.1f} s ({total / 3600:.2f} h)" in part
    assert "| acrobot-budget | 3.0 |" in part and "| CartPole-v1 | – | – | – | – | 0.5 |" in part


def test_paper_track_alone_is_unchanged(reported: dict[str, Any]) -> None:
    paper = _section(reported["md"], "## Table 1 re-measured")
    assert "| CartPole-v1 | ABCO(α) | 1 | 1.000 [1.000, 1.000] |" in paper
    assert "acrobot-budget" not in paper and "Acrobot-v1 |" not in paper
    assert "P: the paper's performance measure" in reported["md"]
    # a run folder of a task without a record yet: the task's, not an env of the paper's
    track = reported["md"].split("## The paper track", 1)[1]
    assert "knn-ifo" not in track and "cartpole-short" not in track.split("## Wall time")[0]
    knn = _table(reported["md"], "cartpole-short")["knn-ifo"]
    assert knn[2:5] == ["other", "0", "–"] and knn[7] == "no finished run |"


def test_headline_value_of_an_older_record() -> None:
    block = {"performance": 0.4, "aer": 1.0}
    assert headline_value({"env": "CartPole-v1", "episodes": block}) == (0.4, False)
    assert headline_value({"env": "CartPole-v1", "episodes": {**block, "score": 0.6}}) == (0.6,
                                                                                          True)
    assert headline_value({"env": "AbcoMaze5x5-v0", "episodes": block}) is None  # train/paper


#: Records with a benchmark key that is not what abco writes, and the reason given.
BAD = {
    "score NaN": ({"episodes": {**_block(0.5), "score": float("nan")}}, "episodes.score is not"),
    "score text": ({"episodes": {**_block(0.5), "score": "1"}}, "episodes.score is not a number"),
    "episode scores short": ({"episodes": {**_block(0.5), "episode_scores": [0.5]}},
                             "episodes.episode_scores does not hold its 2 episodes"),
    "episode scores long": ({"episodes": {**_block(0.5), "episodes": 100_001,
                                          "episode_scores": [0.5] * 100_001}},
                            "holds more than 100,000 episodes"),
    "task slash": ({"task": "a/b"}, "task 'a/b' is not a valid name"),
    "task number": ({"task": 3}, "task is not a name"),
    "budget zero": ({"budget": 0}, "budget is out of range"),
    "budget float": ({"budget": 5.0}, "budget is not an integer"),
    "headline elsewhere": ({"headline": "test/paper"}, "is not an evaluation of the record"),
    "version text": ({"code_version": "1.0"}, "code_version is not"),
    "version keys": ({"code_version": {"version": "1"}}, "code_version is not"),
    "version long": ({"code_version": {"version": "1", "source": "x" * 65}}, "code_version"),
    "seconds negative": ({"seconds": -1.0}, "seconds is below 0.0"),
}  # fmt: skip


@pytest.mark.parametrize("kind", sorted(BAD))
def test_a_bad_benchmark_key_is_refused(kind: str) -> None:
    extra, reason = BAD[kind]
    with pytest.raises(RecordError, match=reason.replace("(", r"\(").replace(")", r"\)")):
        check_final(task_record("cartpole-short", "abco", 0, extra))


def test_a_task_record_belongs_to_its_task_folder() -> None:
    record = task_record("cartpole-short", "abco", 1)
    assert check_final(record, ("cartpole-short", "abco", 1, None)) is record
    assert check_final(record, ("CartPole-v1", "abco", 1, None)) is record
    with pytest.raises(RecordError, match="the record of CartPole-v1/abco/seed1, not of"):
        check_final(record, ("maze5-heldout", "abco", 1, None))
    # a task that trains on K layouts: its records sit in the task's folder, no layouts level
    trained = task_record("maze5-heldout", "abco", 1, {"layouts": 100})
    assert check_final(trained, ("maze5-heldout", "abco", 1, None)) is trained
    assert check_final(trained, ("AbcoMaze5x5-v0", "abco", 1, 100)) is trained
    with pytest.raises(RecordError, match="not of"):
        check_final(trained, ("AbcoMaze5x5-v0", "abco", 1, None))
    assert provenance.version_state(record, THIS) == "this"


def test_a_stopped_run_counts_as_the_random_policy(tmp_path: Path) -> None:
    """A run its method stopped without a result enters the task's mean with score 0 (no
    policy came out of it), so stopping never flatters a method."""
    from abco_train.report.headline import task_cells
    from abco_train.report.runs import load_runs

    root = write_track(tmp_path / "grid", tasks=["cartpole-short"], methods=["abco"])
    stopped = root / "cartpole-short" / "abco" / "seed2" / "final.json"
    record = task_record("cartpole-short", "abco", 2)
    record = {k: v for k, v in record.items() if k not in ("episodes", "headline")}
    stopped.write_text(json.dumps({**record, "status": "idm_at_chance", "message": "at chance",
                                   "iteration": 1}))  # fmt: skip
    cell = task_cells({"cartpole-short": load_runs(root)})["cartpole-short"]["abco"]
    assert cell.stopped == 1 and cell.values[2] == 0.0
    assert cell.mean == pytest.approx((0.8 + 0.81 + 0.0) / 3)


def test_goals_are_checked_with_their_figures(reported: dict[str, Any]) -> None:
    goals = _section(reported["md"], "## Goals of the benchmark track")
    lines = [x for x in goals.splitlines() if x.startswith("- ")]
    assert lines[0].startswith("- missed: Random within ±0.05 of 0")  # not run on one task
    assert "(not run: acrobot-budget)" in lines[0]
    assert lines[1].startswith("- met: Expert within ±0.05 of 1") and "1.010" in lines[1]
    assert lines[2].startswith("- met: headroom") and "at least 3 of 3 tasks: 3" in lines[2]
    assert lines[3].startswith("- met: learnable")
    if aggregates.load_rliable()[0] is None:
        assert lines[4].startswith("- not checked: precision")
    else:
        # every method of the grid is precise; DILO and LAPO, in the track, were not run
        assert lines[4].startswith("- missed: precision") and "Too wide" not in lines[4]
        assert lines[4].endswith("No aggregate: DILO; LAPO")
        assert lines[5].startswith("- missed: precision, every IfO method's mean score 95% "
                                   "interval at most 0.10 wide")
        lines = lines[:5] + lines[6:]
    assert lines[5].startswith("- met: no run over its task's budget")
    assert lines[6].startswith("- not checked: wall time")


def test_precision_checks_the_iqm_strictly_and_the_mean_inclusively() -> None:
    from abco_train.report.headline import IFO_METHODS
    from abco_train.report.headline_goals import _label, _precision

    def row(method: str, mean_width: float, iqm_width: float) -> dict[str, Any]:
        return {"table": "headline-aggregate", "metric": "score", "method": method,
                "ci_low": 0.0, "ci_high": mean_width, "iqm_ci_low": 0.0,
                "iqm_ci_high": iqm_width}  # fmt: skip

    methods = list(IFO_METHODS)
    rows = [row(m, 0.05, 0.05) for m in methods]
    assert [x.split(":")[0] for x in _precision(rows)] == ["- met", "- met"]
    rows[0] = row(methods[0], 0.10, 0.10)  # at the goal: the mean's met, the IQM's not
    iqm, mean = _precision(rows)
    assert iqm.startswith("- missed") and iqm.endswith("Too wide: " + _label(methods[0]))
    assert mean.startswith("- met: precision, every IfO method's mean score")
    assert _precision(rows[1:])[1].endswith(f"No aggregate: {_label(methods[0])}")


def test_a_run_over_its_budget_misses_the_goal(tmp_path: Path) -> None:
    from abco_train.report.headline import task_cells
    from abco_train.report.headline_goals import goals_section
    from abco_train.report.runs import load_runs

    root = write_track(tmp_path / "grid", tasks=["cartpole-short"], methods=["abco", "random"])
    over = root / "cartpole-short" / "abco" / "seed1" / "final.json"
    over.write_text(json.dumps(task_record("cartpole-short", "abco", 1,
                                           {"interactions": {"rl": 5001}})))  # fmt: skip
    runs = load_runs(root)
    lines = goals_section(task_cells({"cartpole-short": runs}), runs, [], 5 * 3600.0)
    budget = next(x for x in lines if "budget" in x)
    assert budget.startswith("- missed") and "cartpole-short/abco/seed1" in budget
    assert next(x for x in lines if "wall time" in x).startswith("- missed")
    assert next(x for x in lines if "precision" in x).startswith("- not checked")


def _cells(best: list[float], expert: float = 1.0) -> dict[str, dict[str, Any]]:
    """Tasks t0, t1, ... whose best IfO method (abco) scores ``best[i]``, with references."""
    import numpy as np

    from abco_train.report.headline import Cell
    from abco_train.report.stats import cell_stats

    def cell(task: str, method: str, value: float) -> Cell:
        c = Cell(task, method, values={0: value})
        c.stats = cell_stats([np.array([value])])
        return c

    return {f"t{i}": {"abco": cell(f"t{i}", "abco", b), "gaifo": cell(f"t{i}", "gaifo", 0.05),
                      "random": cell(f"t{i}", "random", 0.0),
                      "expert": cell(f"t{i}", "expert", expert)}
            for i, b in enumerate(best)}  # fmt: skip


@pytest.mark.parametrize("best, headroom, learnable", [
    ([0.9, 0.9, 0.9, 0.9, 0.9, 1.0, 1.0], "met", "met"),    # 5 of 7 at or below 0.90
    ([0.9, 0.9, 0.9, 0.9, 0.91, 1.0, 1.0], "missed", "met"),  # 4 of 7
    ([0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.1], "met", "missed"),  # t6: none above 0.10
])  # fmt: skip
def test_headroom_and_learnable_at_their_lines(best: list[float], headroom: str,
                                                learnable: str) -> None:  # fmt: skip
    from abco_train.report.headline_goals import goals_section

    lines = goals_section(_cells(best, expert=0.95), [], [], None)
    assert next(x for x in lines if "headroom" in x).startswith(f"- {headroom}: headroom")
    assert next(x for x in lines if "learnable" in x).startswith(f"- {learnable}: learnable")
    assert "at least 5 of 7 tasks" in next(x for x in lines if "headroom" in x)
    # 0.95 lies on the tolerance's line: within it
    assert next(x for x in lines if "Expert" in x).startswith("- met: Expert")


def test_a_run_stopped_over_budget_misses_the_goal(tmp_path: Path) -> None:
    from abco_train.report.headline_goals import goals_section
    from abco_train.report.runs import load_runs

    root = write_track(tmp_path / "grid", tasks=["cartpole-short"], methods=["abco"])
    record = task_record("cartpole-short", "abco", 0, {"status": "over_budget"})
    (root / "cartpole-short" / "abco" / "seed0" / "final.json").write_text(json.dumps(record))
    lines = goals_section({}, load_runs(root), [], None)
    budget = next(x for x in lines if "budget" in x)
    assert budget.startswith("- missed") and "cartpole-short/abco/seed0" in budget


def test_overview_gives_every_method_on_every_task(reported: dict[str, Any]) -> None:
    part = _section(reported["md"], "## Headline: the benchmark track")
    table = part.split("| Method | Role | ", 1)[1].split("\n\n", 1)[0].splitlines()
    tasks = table[0].rstrip(" |").split(" | ")
    rows = {r.split(" | ")[0].lstrip("| "): r.rstrip(" |").split(" | ")[2:] for r in table[2:]}
    assert sorted(tasks) == sorted(TASKS)
    column = dict(zip(tasks, range(len(tasks))))
    assert rows["ABCO(α)"] == ["0.810"] * 3  # 0.8 + the seeds' 0.00-0.02
    assert rows["BC"][column["maze5-heldout"]] == "0.910 (P)"  # older records: their P
    assert rows["Random"][column["acrobot-budget"]] == "–"  # not run there
    assert list(rows)[-3:] == ["BC", "Expert", "Random"]


@pytest.mark.parametrize("wall_s, verdict", [(3 * 3600.0, "not yet"), (5 * 3600.0, "missed")])
def test_an_unfinished_grid_has_no_wall_time_verdict_yet(wall_s: float, verdict: str) -> None:
    from abco_train.report.headline_goals import goals_section

    why = "its last `abco bench` session stopped before its end; 556 of 700 cells done"
    lines = goals_section({}, [], [], wall_s, why)
    assert lines[-1].startswith(f"- {verdict}: the grid within 4 h")
    assert "556 of 700 cells" in lines[-1] and "The grid is not finished" in lines[2]
    assert goals_section({}, [], [], wall_s)[-1].startswith(
        "- met" if wall_s < 4 * 3600 else "- missed")


def test_the_report_reads_an_unfinished_grid_from_its_log(tmp_path: Path) -> None:
    from abco_train.report.runs import Grid, load_runs
    from abco_train.report.tables import wall

    root = write_track(tmp_path / "grid", tasks=["cartpole-short"], methods=["abco"])
    session = {"started": "2026-01-01T00:00:00+00:00", "wall_s": 100.0, "backend": "local",
               "jobs": 2, "threads": 1, "cells": 9, "ran": 3, "skipped": 0, "failed": [],
               "argv": ["bench"], "results": "results.jsonl"}  # fmt: skip
    log = root / "bench_log.jsonl"
    log.write_text(json.dumps({**session, "finished": False}) + "\n")
    grid = Grid(load_runs(root))
    timed, _ = wall(root, grid)
    assert timed.seconds == 100.0 and timed.unfinished is not None
    assert f"{len(grid.done)} of 9 cells done" in timed.unfinished
    log.write_text(json.dumps({**session, "finished": True}) + "\n")
    assert wall(root, grid)[0].unfinished is None


def test_the_aggregates_plot_has_room_for_few_methods(tmp_path: Path) -> None:
    import struct

    from abco_train.report.aggregates import load_rliable
    from abco_train.report.headline import HEADLINE_LABELS
    from abco_train.report.headline_plots import plot_aggregates

    rl = load_rliable()[0]
    if rl is None:
        pytest.skip("rliable is not installed")
    interval = {m: (0.5, 0.4, 0.6) for m in ("bco", "abco", "gaifo")}
    png = plot_aggregates(interval, interval, rl, HEADLINE_LABELS, tmp_path / "a.png")
    # rliable alone makes 0.45 in a row (135 px at 100 dpi for three): the titles, the
    # labels and the bars overlapped
    height = struct.unpack(">I", png.read_bytes()[20:24])[0]  # the PNG header's height
    assert height >= 250
