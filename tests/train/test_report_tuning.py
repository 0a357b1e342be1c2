"""The tuning record (``abco report TUNING --tuning defaults,lr-div3``): synthetic validation
grids of two configurations on a two-family track; the better mean is kept per method and
family, a tie keeps the defaults, a stopped run counts 0 and a missing run decides nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from abco_train.bench.tasks import load_track
from abco_train.cli import main
from abco_train.report.runs import ReportError
from abco_train.report.tuning import choose, tuning_record

TRACK = """
[track]
name = "mini"
methods = ["random", "bco", "abco"]
validation_seeds = "100-101"
test_seeds = "1000-1001"

[[task]]
name = "cartpole"
env = "CartPole-v1"
budget = 20000

[[task]]
name = "acrobot"
env = "Acrobot-v1"
budget = 30000

[[task]]
name = "maze"
env = "AbcoMaze5x5-v0"
budget = 40000
headline = "test/paper"
"""
HEAD = {"cartpole": "episodes", "acrobot": "episodes", "maze": "test/paper"}
ENV = {"cartpole": "CartPole-v1", "acrobot": "Acrobot-v1", "maze": "AbcoMaze5x5-v0"}
#: config -> method -> task -> score of each seed (None: the method stopped the run)
SCORES = {
    "defaults": {"bco": {"cartpole": [1.0, 1.0], "acrobot": [0.2, 0.4], "maze": [0.5, 0.5]},
                 "abco": {"cartpole": [1.0, 1.0], "acrobot": [0.6, 0.6], "maze": [0.7, 0.9]},
                 "random": {"cartpole": [0.0, 0.0], "acrobot": [0.0, 0.0], "maze": [0.0, 0.0]}},
    "lr-div3": {"bco": {"cartpole": [1.0, 1.0], "acrobot": [0.5, 0.6], "maze": [0.5, 0.5]},
                "abco": {"cartpole": [1.0, None], "acrobot": [0.9, 0.9], "maze": [0.8]}},
}  # fmt: skip


def _record(root: Path, config: str, task: str, method: str, seed: int,
            value: float | None) -> None:  # fmt: skip
    run = root / config / task / method / f"seed{seed}"
    run.mkdir(parents=True)
    head = HEAD[task]
    final = {"env": ENV[task], "method": method, "seed": seed, "task": task,
             "budget": 1000, "headline": head,
             "status": "ok" if value is not None else "idm_at_chance"}  # fmt: skip
    if value is not None:
        final[head] = {"performance": value, "aer": value, "score": value,
                       "episode_scores": [value], "episodes": 1}  # fmt: skip
    (run / "final.json").write_text(json.dumps(final))
    (run / "config.json").write_text(json.dumps({"task": task}))


def _write(root: Path) -> Path:
    for config, methods in SCORES.items():
        for method, tasks in methods.items():
            for task, values in tasks.items():
                for seed, value in zip((100, 101), values):
                    _record(root, config, task, method, seed, value)
    (root / "mini.toml").write_text(TRACK)
    return root


@pytest.fixture
def tuning(tmp_path: Path) -> Path:
    return _write(tmp_path)


def test_choose_keeps_the_first_on_a_tie() -> None:
    assert choose({"defaults": 0.4, "b": 0.4}) == "defaults"
    assert choose({"defaults": 0.4, "b": 0.41}) == "b"


def test_record_keeps_the_better_mean_per_family(tuning: Path) -> None:
    track = load_track(tuning / "mini.toml")
    record = tuning_record(tuning, ["defaults", "lr-div3"], track, [100, 101])
    assert record.families == {"classic": ("cartpole", "acrobot"), "maze": ("maze",)}
    bco_classic = record.results[("bco", "classic")]
    assert bco_classic.mean("defaults") == pytest.approx(0.65)
    assert bco_classic.mean("lr-div3") == pytest.approx(0.775)
    # a stopped run counts 0: abco's classic mean under lr-div3 is (1 + 0 + 0.9 + 0.9) / 4
    abco_classic = record.results[("abco", "classic")]
    assert abco_classic.mean("lr-div3") == pytest.approx(0.7)
    choices = record.choices()
    assert choices["bco"] == {"classic": "lr-div3", "maze": "defaults"}  # the maze: a tie
    assert choices["abco"]["classic"] == "defaults"  # 0.8 against 0.7
    assert choices["abco"]["maze"] is None  # seed 101 of lr-div3 missing
    assert "random" not in choices  # a reference: nothing to tune
    assert abco_classic.missing["lr-div3"] == []
    assert record.results[("abco", "maze")].missing["lr-div3"] == [("maze", 101)]


def test_cli_writes_the_record(tuning: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["report", str(tuning), "--tuning", "defaults,lr-div3",
                 "--track", str(tuning / "mini.toml")])  # fmt: skip
    assert code == 0
    choices = json.loads((tuning / "choices.json").read_text())
    assert choices["configs"] == ["defaults", "lr-div3"] and choices["seeds"] == [100, 101]
    assert choices["choices"]["bco"]["classic"] == "lr-div3"
    text = (tuning / "tuning.md").read_text()
    assert "| bco | classic | 0.650 (4 runs) | 0.775 (4 runs) | lr-div3 |" in text
    assert "not decided: runs missing" in text
    assert "| maze | 101 | 0.900 | missing |" in text


def test_an_overlay_replaces_the_base_cells_it_holds(tuning: Path) -> None:
    # a re-run of abco's maze cells (a default that changed): its runs stand in for the base's
    for seed, value in zip((100, 101), (0.1, 0.3)):
        _record(tuning, "rerun", "maze", "abco", seed, value)
    track = load_track(tuning / "mini.toml")
    record = tuning_record(tuning, ["defaults+rerun", "lr-div3"], track, [100, 101])
    assert record.configs == ("defaults+rerun", "lr-div3")
    assert record.results[("abco", "maze")].mean("defaults+rerun") == pytest.approx(0.2)
    assert record.results[("bco", "maze")].mean("defaults+rerun") == pytest.approx(0.5)
    assert record.results[("abco", "classic")].mean("defaults+rerun") == pytest.approx(0.8)
    with pytest.raises(ReportError, match="no configuration folder"):
        tuning_record(tuning, ["defaults+nope"], track, [100, 101])


def test_cli_refuses_a_missing_configuration(tuning: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["report", str(tuning), "--tuning", "defaults,nope",
                 "--track", str(tuning / "mini.toml")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "no configuration folder" in err and len(err.strip().splitlines()) == 1
    assert not (tuning / "choices.json").exists()


def test_a_damaged_record_is_named_in_the_record(tuning: Path) -> None:
    (tuning / "lr-div3" / "maze" / "bco" / "seed100" / "final.json").write_text("{not json")
    assert main(["report", str(tuning), "--tuning", "defaults,lr-div3",
                 "--track", str(tuning / "mini.toml")]) == 0  # fmt: skip
    text = (tuning / "tuning.md").read_text()
    assert "## Records left out" in text and "lr-div3/maze/bco/seed100" in text
    choices = json.loads((tuning / "choices.json").read_text())
    assert choices["choices"]["bco"]["maze"] is None  # that run is missing: no choice


def test_out_must_be_a_folder(tuning: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tuning / "file").write_text("x")
    assert main(["report", str(tuning), "--tuning", "defaults", "--track",
                 str(tuning / "mini.toml"), "--out", str(tuning / "file")]) == 2  # fmt: skip
    assert "is not a folder" in capsys.readouterr().err
