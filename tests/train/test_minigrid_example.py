"""docs/examples/minigrid.md runs: its commands, as written, at a tiny size (fewer episodes and
transitions, one iteration, one seed)."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest
from test_bench_grid import tiny_overrides

import abco_data
from abco_train.cli import main as abco_main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "docs" / "examples"
DOC = EXAMPLES / "minigrid.md"
TRACK = EXAMPLES / "minigrid_track.toml"
#: Flags made small, by command; everything else as the page has it.
TINY_COUNTS = {"--episodes": "5", "--transitions": "300", "--seeds": "0"}
TINY_RECORD = ["--reference-episodes", "3", "--reference-expert-episodes", "2", "--quiet"]
TINY_TRAINING = ["--iterations", "1", "--idm-epochs", "1", "--policy-epochs", "1",
                 "--eval-episodes", "3", "--threads", "1", "--quiet"]  # fmt: skip


def _commands(text: str) -> list[list[str]]:
    """The ``abco`` command lines of the page's bash blocks."""
    blocks = re.findall(r"^```bash\n(.*?)^```", text, re.S | re.M)
    return [shlex.split(line, comments=True) for block in blocks
            for line in block.replace("\\\n", " ").splitlines() if line.startswith("abco ")]


def _tiny(argv: list[str], track: Path) -> list[str]:
    out = [TINY_COUNTS.get(argv[i - 1], a) if i else a for i, a in enumerate(argv)]
    out = [str(track) if a == "docs/examples/minigrid_track.toml" else a for a in out]
    if out[1:3] == ["data", "record"]:
        return out + TINY_RECORD
    if out[1] == "train":
        return out + TINY_TRAINING + ["--no-plots"]
    if out[1] == "bench":
        return out + TINY_TRAINING + ["--jobs", "2"]
    return out


def _tiny_track(path: Path, data: dict[str, str]) -> Path:
    """The page's track with small pre-demonstrations, CartPole on tiny datasets."""
    text = TRACK.read_text().replace("pre_transitions = 35000", "pre_transitions = 300")
    cartpole = (f'settings = {{ pre_transitions = 300, expert_data = "{data["expert_data"]}", '
                f'pre_data = "{data["pre_data"]}" }}')  # fmt: skip
    text = text.replace("settings = { pre_transitions = 10000 }", cartpole)
    assert cartpole in text and '-pre-v0", pre_transitions = 300 }' in text  # the room's
    path.write_text(text)
    return path


def test_the_page_shows_the_example_files() -> None:
    text = DOC.read_text()
    shown = re.findall(r'--8<-- "([^"]+)"', text)
    assert sorted(shown) == ["docs/examples/minigrid_example.py",
                             "docs/examples/minigrid_track.toml"]  # fmt: skip
    assert all((ROOT / path).is_file() for path in shown)


def test_the_minigrid_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("minigrid")
    monkeypatch.setenv("ABCO_DATA_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("PYTHONPATH", str(EXAMPLES))  # as the page says; the bench's workers
    monkeypatch.syspath_prepend(str(EXAMPLES))  # this process: --env imports the module
    monkeypatch.chdir(tmp_path)  # the page's runs/ folders land here
    track = _tiny_track(tmp_path / "track.toml", tiny_overrides(tmp_path / "cartpole"))
    commands = _commands(DOC.read_text())
    assert [argv[1] for argv in commands] == ["data", "data", "train", "train", "bench",
                                              "report"]  # fmt: skip
    for argv in commands:
        assert abco_main(_tiny(argv, track)[1:]) == 0, argv
    expert = abco_data.load("local/grid-empty-expert-v0")
    assert expert.reference.expert_mean > expert.reference.random_mean
    for run in ("grid-abco", "grid-bco"):
        final = json.loads((tmp_path / "runs" / run / "final.json").read_text())
        assert final["status"] == "ok" and 0 <= final["episodes"]["success_rate"] <= 1
    report = (tmp_path / "runs" / "grid-bench" / "report" / "report.md").read_text()
    for task in ("grid-empty", "cartpole"):  # both tasks, in the same tables
        section = report.split(f"### {task}\n", 1)[1].split("\n### ", 1)[0]
        for method in ("ABCO(α)", "BCO", "Expert", "Random"):
            assert f"| {method} |" in section, (task, method)
