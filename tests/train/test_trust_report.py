"""``abco report`` on grids you cannot trust: every crafted record is named, skipped and
counted (never a traceback, never a result), text from records cannot forge a line, the
summary says first what ran, and full or read-only disks leave the previous report intact."""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path
from typing import Any

import pytest

from abco_train.bench.records import check_final, escape
from abco_train.cli import main as abco_main
from abco_train.report.runs import load_runs
from abco_train.report.write import write_report

ENV = "CartPole-v1"


def _final(method: str = "abco", seed: int = 0, p: float = 1.0, **extra: Any) -> dict[str, Any]:
    score = {"performance": p, "aer": 500 * p, "success_rate": 1.0, "episodes": 2,
             "episode_performance": [p, p], "episode_returns": [500 * p, 500 * p]}  # fmt: skip
    return {"env": ENV, "method": method, "seed": seed, "status": "ok", "episodes": score,
            **extra}  # fmt: skip


def _grid(root: Path) -> Path:
    """A small valid grid: abco seeds 0-1 finished, bc seed 0 finished."""
    rows = []
    for method, seed in (("abco", 0), ("abco", 1), ("bc", 0)):
        run_dir = root / ENV / method / f"seed{seed}"
        run_dir.mkdir(parents=True)
        (run_dir / "final.json").write_text(json.dumps(_final(method, seed)))
        record = {"iteration": 0, "eval": {"performance": 0.5}, "label_distribution": [0.5, 0.5]}
        (run_dir / "metrics.jsonl").write_text(json.dumps(record) + "\n")
        rows.append({"env": ENV, "method": method, "seed": seed, "status": "done",
                     "final": _final(method, seed), "wall_s": 2.0,
                     "reference": {"expert": 500.0, "random": 20.0}})  # fmt: skip
    (root / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (root / "bench_log.jsonl").write_text(json.dumps({"started": "s", "wall_s": 6.0, "ran": 3})
                                          + "\n")  # fmt: skip
    return root


def _report(root: Path, out: Path) -> tuple[str, list[dict[str, str]]]:
    files = write_report(root, out, labels_env=ENV)
    with files["csv"].open() as f:
        return files["report"].read_text(), list(csv.DictReader(f))


def _summary(md: str) -> str:
    return md.split("## Summary", 1)[1].split("\n## ", 1)[0]


def test_the_summary_says_first_what_ran(tmp_path: Path) -> None:
    root = _grid(tmp_path / "runs")
    md, _ = _report(root, tmp_path / "out")
    assert md.index("## Summary") < md.index("## Goals") < md.index("## Table 1")
    summary = _summary(md)
    assert "3 cells: 3 finished; 1 missing from the grid they span" in summary
    assert f"- {ENV}: 2 methods × seeds 0-1, 3 of 4 cells finished; bc: seed 1 missing" in summary
    assert "No record skipped" in summary
    # no row for an environment abco never ran: one line says where it did not run
    goals = md.split("## Goals", 1)[1].split("\n## ", 1)[0]
    assert goals.count("| Acrobot-v1 |") == 0 and "not run" not in goals
    assert "- ABCO(α): no run on Acrobot-v1, MountainCar-v0," in goals
    assert "- IUPE: no run on any environment in this grid." in goals


#: Crafted records, one per schema rule: (file under the grid, its content, the reason given).
FINAL = f"{ENV}/abco/seed1/final.json"
CRAFTED: dict[str, tuple[str, str | bytes, str]] = {
    "final {}": (FINAL, "{}", "no env"),
    "final list": (FINAL, "[1]", "not a JSON object"),
    "final truncated": (FINAL, '{"env": "CartPole-v1", "meth', "not JSON"),
    "final not UTF-8": (FINAL, b'{"env": "\xff\xfe"}', "not UTF-8"),
    "final deeply nested": (FINAL, "[" * 200_000 + "]" * 200_000, "nested too deeply"),
    "final NaN P": (FINAL, json.dumps(_final(seed=1, p=float("nan"))), "not a finite number"),
    "final Infinity AER": (FINAL, json.dumps(_final(seed=1)).replace('"aer": 500.0',
                                                                     '"aer": Infinity'),
                           "episodes.aer is not a finite number"),
    "final huge number": (FINAL, json.dumps(_final(seed=1)).replace('"seed": 1', '"seed": 1e400'),
                          "seed is not an integer"),
    "final seed text": (FINAL, json.dumps(_final(seed=1)).replace('"seed": 1', '"seed": "1"'),
                        "seed is not an integer"),
    "final other cell": (FINAL, json.dumps(_final(seed=0)), "the record of CartPole-v1/abco/seed0"),
    "final no evaluation": (FINAL, json.dumps({k: v for k, v in _final(seed=1).items()
                                               if k != "episodes"}), "without any evaluation"),
    "final episodes text": (FINAL, json.dumps(_final(seed=1, p=1.0)).replace(
        '"episode_returns": [500.0', '"episode_returns": ["x"'), "is not a number"),
    "final empty episodes": (FINAL, json.dumps(_final(seed=1)).replace('[500.0, 500.0]', '[]'),
                             "episodes.episode_returns does not hold its 2 episodes"),
    "final status forged": (FINAL, json.dumps({**_final(seed=1), "status": "ok\nforged"}),
                            "status is not a status name"),
    "final interactions": (FINAL, json.dumps(_final(seed=1, interactions={"rl": -1})),
                           "interactions.rl is out of range"),
    "final huge count": (FINAL, json.dumps(_final(seed=1, interactions={"rl": 10**30})),
                         "interactions.rl is too large"),
    "row truncated": ("results.jsonl", '{"env": "CartPole-v1", "me', "not JSON"),
    "row without env": ("results.jsonl", json.dumps({"method": "bc", "seed": 0, "status": "done"}),
                        "no env"),
    "row seed overflow": ("results.jsonl", '{"env": "CartPole-v1", "method": "bc", "seed": 1e400,'
                          ' "status": "done"}', "seed is not an integer"),
    "row negative seed": ("results.jsonl", json.dumps({"env": ENV, "method": "bc", "seed": -1,
                                                       "status": "done"}), "out of range"),
    "row NaN wall": ("results.jsonl", json.dumps({"env": ENV, "method": "bc", "seed": 0,
                                                  "status": "done", "wall_s": float("nan")}),
                     "wall_s is not a finite number"),
    "row reference text": ("results.jsonl", json.dumps(
        {"env": ENV, "method": "bc", "seed": 0, "status": "done",
         "reference": {"expert": "500", "random": 0.0}}), "reference.expert is not a number"),
    "row error not text": ("results.jsonl", json.dumps({"env": ENV, "method": "bc", "seed": 0,
                                                        "status": "failed", "error": [1]}),
                           "error is not text"),
    "log NaN wall": ("bench_log.jsonl", '{"wall_s": NaN, "ran": 1}', "not a finite number"),
    "log wall text": ("bench_log.jsonl", '{"wall_s": "12", "ran": 1}', "wall_s is not a number"),
    "log failed not list": ("bench_log.jsonl", '{"wall_s": 1.0, "failed": 3}',
                            "failed is not a list"),
    "log not object": ("bench_log.jsonl", "[]", "not a JSON object"),
    "config list": (f"{ENV}/abco/seed0/config.json", "[]", "not a JSON object"),
    "config preset": (f"{ENV}/abco/seed0/config.json", json.dumps({"preset": "cpu\n## x"}),
                      "preset is not a name"),
    "metrics negative": (f"{ENV}/abco/seed0/metrics.jsonl", '{"iteration": -1}',
                         "iteration is out"),
    "metrics huge": (f"{ENV}/abco/seed0/metrics.jsonl", '{"iteration": 1000000000}',
                     "iteration is out"),
    "metrics Infinity": (f"{ENV}/abco/seed0/metrics.jsonl",
                         '{"iteration": 0, "eval": {"performance": Infinity}}', "not a finite"),
    "metrics shares": (f"{ENV}/abco/seed0/metrics.jsonl",
                       '{"iteration": 0, "label_distribution": ["a"]}', "is not a number"),
    "metrics many actions": (f"{ENV}/abco/seed0/metrics.jsonl", json.dumps(
        {"iteration": 0, "label_distribution": [0.01] * 100}), "more than 64 actions"),
}


@pytest.mark.parametrize("kind", sorted(CRAFTED))
def test_a_crafted_record_is_skipped_and_counted(tmp_path: Path, kind: str) -> None:
    root = _grid(tmp_path / "runs")
    name, content, reason = CRAFTED[kind]
    path = root / name
    path.parent.mkdir(parents=True, exist_ok=True)
    data = content if isinstance(content, bytes) else content.encode()
    if path.name.endswith(".jsonl"):  # one more line
        data = (path.read_bytes() if path.exists() else b"") + data + b"\n"
    path.write_bytes(data)
    md, rows = _report(root, tmp_path / "out")
    summary = _summary(md)
    assert "1 record skipped" in summary
    line = next(x for x in summary.splitlines() if x.startswith(f"- {name}"))
    assert reason in line, line
    if name == FINAL:  # the cell is not a finished run
        assert "3 cells: 2 finished, 1 with a damaged final.json" in summary
        assert "abco: seed 1 damaged" in summary
    for text in (md, *(json.dumps(r) for r in rows)):
        assert "nan" not in text.lower().replace("nanoseconds", "")
        assert "inf " not in text.lower() and "forged" not in text and "## x" not in text


@pytest.mark.parametrize("name", ["seed٣", "seed²", "seed03", "seed-1", "seed99999999999"])
def test_a_seed_folder_name_in_other_digits_is_no_seed(tmp_path: Path, name: str) -> None:
    root = _grid(tmp_path / "runs")
    odd = root / ENV / "abco" / name
    odd.mkdir()
    (odd / "final.json").write_text(json.dumps(_final(seed=3)))
    runs = load_runs(root, skipped := [])
    assert sorted(r.seed for r in runs) == [0, 0, 1]
    assert [s.where for s in skipped] == [f"{ENV}/abco/{name}"]
    md, _ = _report(root, tmp_path / "out")
    assert "seeds 0-1" in _summary(md) and "seed 3" not in md


@pytest.mark.parametrize("kind", ["folder", "/dev/zero", "fifo", "broken link"])
def test_a_record_that_is_not_a_file_is_skipped_unread(tmp_path: Path, kind: str) -> None:
    root = _grid(tmp_path / "runs")
    for name in ("results.jsonl", f"{ENV}/abco/seed1/final.json",
                 f"{ENV}/abco/seed0/metrics.jsonl"):  # fmt: skip
        path = root / name
        path.unlink()
        if kind == "folder":
            path.mkdir()
        elif kind == "fifo":
            os.mkfifo(path)
        else:
            path.symlink_to("/dev/zero" if kind == "/dev/zero" else root / "nowhere")
    md, _ = _report(root, tmp_path / "out")
    summary = _summary(md)
    if kind == "broken link":  # as if absent
        assert "No record skipped" in summary
    else:
        assert "3 records skipped" in summary and summary.count("not a regular file") == 3


def test_text_from_records_cannot_forge_a_line(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    root = _grid(tmp_path / "runs")
    stopped = root / ENV / "bco" / "seed0"
    stopped.mkdir(parents=True)
    (stopped / "final.json").write_text(json.dumps(
        {"env": ENV, "method": "bco", "seed": 0, "status": "idm_at_chance",
         "message": "at chance\n## Forged section\r\nerror: forged\x1b[31m\u2028x"}))
    failed = {"env": ENV, "method": "bc", "seed": 1, "status": "failed", "final": None,
              "error": "RuntimeError: boom\n| forged | row |"}  # fmt: skip
    (root / ENV / "bc" / "seed1").mkdir()
    with (root / "results.jsonl").open("a") as f:
        f.write(json.dumps(failed) + "\n")
    with (root / "bench_log.jsonl").open("a") as f:
        f.write(json.dumps({"started": "2026\n- forged session", "wall_s": 1.0, "ran": 1,
                            "backend": "local\x1b[2J"}) + "\n")  # fmt: skip
    run_dir = root / ENV / "abco" / "seed0"
    final = _final(seed=0)
    final["episodes\nforged"] = final["episodes"]  # an evaluation's name, into the CSV
    (run_dir / "final.json").write_text(json.dumps(final))
    odd = root / ENV / "ab\nco"
    (odd / "seed0").mkdir(parents=True)
    assert abco_main(["report", str(root), "--out", str(tmp_path / "out"), "--labels-env",
                      ENV]) == 0  # fmt: skip
    printed = capsys.readouterr()
    md = (tmp_path / "out" / "report.md").read_text()
    table = (tmp_path / "out" / "results.csv").read_text()
    for text in (md, table, printed.out + printed.err):
        lines = text.splitlines()
        assert not any("forged" in x and not ("\\n" in x or "\\r" in x) for x in lines)
        assert "\x1b" not in text and "\u2028" not in text
        assert not any(x.startswith(("## Forged", "error: forged", "- forged")) for x in lines)
    assert "at chance\\n## Forged section\\r\\nerror: forged\\x1b[31m\\u2028x" in md
    assert "ab\\nco: not a valid name" not in md and "method 'ab\\\\nco' is not a valid name" in md
    assert "episodes\\nforged" in table


def test_report_on_a_folder_of_damaged_records_only(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "runs"
    (root / ENV / "abco" / "seed٣").mkdir(parents=True)
    (root / "results.jsonl").write_text('{"env": \n')
    code = abco_main(["report", str(root), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("error: ")
    assert "holds no run folders ({env}/{method}/seed{n}) (2 skipped, the first:" in err
    assert "results.jsonl line 1: not JSON" in err
    assert not (tmp_path / "out").exists()


def test_every_published_record_passes(tmp_path: Path) -> None:
    """The schemas read every record of the published grids (no false alarm)."""
    root = Path(__file__).resolve().parents[2] / "docs" / "results"
    for grid in (root / "runs", root / "generalisation" / "runs"):
        skipped: list[Any] = []
        runs = load_runs(grid, skipped)
        for r in runs[:40]:
            r.metrics()
        assert skipped == [] and all(r.status == "ok" for r in runs)
        assert all(check_final(r.final) for r in runs if r.final)


def test_every_published_benchmark_track_record_passes() -> None:
    """The headline grid's and the budget curves' records, scores, tasks and budgets included,
    pass the schemas; a run its method stopped is a record too, never a damaged one."""
    root = Path(__file__).resolve().parents[2] / "docs" / "results" / "headline"
    for grid in (root / "runs", root / "budget-curves"):
        skipped: list[Any] = []
        runs = load_runs(grid, skipped)
        assert skipped == [] and runs
        assert all(r.status not in ("damaged", "unfinished") for r in runs)
        assert all(check_final(r.final) and r.final.get("task") and r.final.get("budget")
                   for r in runs if r.final)  # fmt: skip


def test_escape_keeps_printable_text() -> None:
    assert escape("BCO(α) – ok") == "BCO(α) – ok"
    assert escape("a\tb\x00c\u202ed") == "a\\tb\\x00c\\u202ed"
    assert escape("x" * 400).endswith("...") and len(escape("x" * 400)) == 300


# -- full and read-only disks -------------------------------------------------------------------


@pytest.fixture
def small_disk(tmp_path: Path) -> Any:
    """A 2 MiB tmpfs (skipped where mounting is not allowed), unmounted afterwards."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)],
                          capture_output=True)  # fmt: skip
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.decode().strip()})")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.parametrize("disk", ["full", "read-only"])
def test_a_failing_disk_leaves_the_previous_report(tmp_path: Path, small_disk: Path,
                                                   disk: str,
                                                   capsys: pytest.CaptureFixture[str]
                                                   ) -> None:  # fmt: skip
    root = _grid(tmp_path / "runs")
    out = small_disk / "report"
    write_report(root, out, labels_env=ENV)
    before = _snapshot(out)
    assert before["report.md"] and before["results.csv"]
    seed2 = root / ENV / "abco" / "seed2"  # the next report and its plots would differ
    seed2.mkdir()
    (seed2 / "final.json").write_text(json.dumps(_final(seed=2, p=0.5)))
    (seed2 / "metrics.jsonl").write_text(json.dumps({"iteration": 0, "eval": {"performance": 0.1},
                                                     "label_distribution": [0.9, 0.1]}) + "\n")
    if disk == "full":
        with pytest.raises(OSError), (small_disk / "filler").open("wb") as f:
            while True:
                f.write(b"\0" * 65536)
                f.flush()
    else:
        subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], check=True)
    capsys.readouterr()
    code = abco_main(["report", str(root), "--out", str(out), "--labels-env", ENV])
    err = capsys.readouterr().err
    assert code == 1 and err.startswith("error: ") and err.count("\n") == 1
    assert _snapshot(out) == before  # every file as it was: none half-written, none added


@pytest.mark.parametrize("kind", ["/dev/null", "a file", "a FIFO at report.md",
                                  "a folder at results.csv", "a link at report.md"])
def test_report_never_replaces_what_is_not_its_file(tmp_path: Path, kind: str,
                                                    capsys: pytest.CaptureFixture[str]
                                                    ) -> None:  # fmt: skip
    import stat

    root = _grid(tmp_path / "runs")
    out, victim = tmp_path / "out", tmp_path / "out"
    if kind == "/dev/null":
        out = victim = Path("/dev/null")
    elif kind == "a file":
        out.write_text("mine")
    else:
        out.mkdir()
        victim = out / kind.split(" at ")[1]
        {"a FIFO": lambda: os.mkfifo(victim), "a folder": victim.mkdir,
         "a link": lambda: victim.symlink_to(tmp_path / "elsewhere.md")}[kind.split(" at ")[0]]()
    mode = victim.lstat().st_mode
    code = abco_main(["report", str(root), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1
    assert victim.lstat().st_mode == mode and stat.S_IFMT(mode) != 0
    if kind == "a file":
        assert out.read_text() == "mine"
    elif out.is_dir():
        assert [p.name for p in out.iterdir()] == [victim.name]  # nothing else written
    assert not (tmp_path / "elsewhere.md").exists()


def test_a_reference_of_other_actions_is_not_drawn(tmp_path: Path) -> None:
    root = _grid(tmp_path / "runs")
    rows = (root / "results.jsonl").read_text().replace(
        '"random": 20.0}', '"random": 20.0, "expert_actions": [1.0]}')
    (root / "results.jsonl").write_text(rows)
    md, _ = _report(root, tmp_path / "out")
    assert "No record skipped" in md and (tmp_path / "out" / "idm_label_distribution.png").exists()


def test_a_folder_spanning_too_many_cells_is_refused(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    from abco_train.report import write

    root = _grid(tmp_path / "runs")
    monkeypatch.setattr(write, "MAX_SPAN", 100)
    with pytest.raises(write.ReportError, match="span more cells than a report covers"):
        write_report(root, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_an_unknown_labels_env_is_refused(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    root = _grid(tmp_path / "runs")
    code = abco_main(["report", str(root), "--out", str(tmp_path / "out"), "--labels-env",
                      "NoSuch-v0"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "unknown --labels-env 'NoSuch-v0'" in err and "envs found: CartPole-v1" in err
    assert not (tmp_path / "out").exists()
