"""The normalised score: its references under each protocol, the reference methods, the keys
of ``final.json``, and the code version every record carries."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from train_testing import tiny_config

import abco_data
from abco_envs.maze.pool import layout_pool
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.code_version import source_digest
from abco_train.harness.evaluation import format_table
from abco_train.harness.loop import train
from abco_train.harness.rollouts import rollout, score

REPO = Path(__file__).resolve().parents[2]


def test_protocol_references_fit_their_protocol():
    cells = np.asarray(layout_pool(3).split("train")[:4])
    paper = abco_data.protocol_reference(cells, "paper", episodes=200)
    standard = abco_data.protocol_reference(cells, "standard", episodes=200)
    # a random walk revisits cells: the paper's 4th-visit rule costs it -1 on most layouts
    assert paper.random_mean < standard.random_mean
    np.testing.assert_array_equal(paper.expert_per_layout, standard.expert_per_layout)
    again = abco_data.protocol_reference(cells, "paper", episodes=200)
    np.testing.assert_array_equal(paper.random_per_layout, again.random_per_layout)
    capped = abco_data.protocol_reference(cells, "standard", 2, episodes=20)
    assert np.all(capped.expert_per_layout < 0)  # no 3x3 path is 2 steps long: never reached
    with pytest.raises(ValueError, match="unknown protocol"):
        abco_data.protocol_reference(cells, "other")


@pytest.mark.parametrize("protocol", ["paper", "standard"])
def test_random_walk_references_match_the_evaluation_path(protocol):
    """The vectorised walks apply the rules :func:`rollout` applies: uniform random actions
    through the real env score about 0 against them."""
    layouts = np.asarray(layout_pool(3).split("test")[:3])
    repeated = np.repeat(layouts, 300, axis=0)
    rng = np.random.default_rng(7)
    roll = rollout(lambda obs: rng.integers(4, size=len(obs)), "AbcoMaze3x3-v0",
                   protocol=protocol, layouts=repeated, env_kwargs={"image_size": 16})
    ref = abco_data.protocol_reference(layouts, protocol, episodes=300)
    result = score(roll, ref, score_reference=ref)
    assert abs(result["score"]) < 0.1, result["score"]


def test_reference_methods_score_zero_and_one(tiny_data, tmp_path):
    expert = train(tiny_config("AbcoMaze3x3-v0", "expert", tiny_data, tmp_path / "e",
                               eval_layouts=5, eval_max_steps=None))  # fmt: skip
    assert expert is not None
    for block in ("train/paper", "train/standard", "test/paper", "test/standard"):
        assert expert[block]["score"] == pytest.approx(1.0)
        assert expert[block]["episode_scores"] == pytest.approx([1.0] * 5)
    assert sum(expert["interactions"].values()) == 0
    random = train(tiny_config("CartPole-v1", "random", tiny_data, tmp_path / "r",
                               eval_episodes=300, eval_max_steps=None))  # fmt: skip
    assert random is not None
    assert abs(random["episodes"]["score"]) < 0.1, random["episodes"]["score"]


def test_final_record_names_task_budget_headline_and_code(tiny_data, tmp_path):
    final = train(tiny_config("AbcoMaze3x3-v0", "bco", tiny_data, tmp_path / "run",
                              iterations=0, task="mine", budget=10**6,
                              headline="test/paper"))  # fmt: skip
    assert final is not None
    assert (final["task"], final["budget"], final["headline"]) == ("mine", 10**6, "test/paper")
    assert set(final["code_version"]) == {"version", "source"}
    assert all("score" in final[k] for k in ("train/paper", "test/standard"))
    table = format_table(final)
    assert "score" in table.splitlines()[1]
    assert [line for line in table.splitlines() if line.endswith("*")][0].startswith("test/paper")
    record = json.loads((tmp_path / "run" / "final.json").read_text())
    assert record["headline"] == "test/paper"


def test_default_headline_and_a_bad_one():
    assert RunConfig(env="CartPole-v1", headline="episodes").validate()
    with pytest.raises(ConfigError, match="--headline must be one of"):
        RunConfig(env="CartPole-v1", headline="test/paper").validate()
    with pytest.raises(ConfigError, match="fresh"):
        RunConfig(env="AbcoMaze3x3-v0", headline="fresh/paper").validate()


def test_code_version_follows_code_not_docstrings(tmp_path):
    for package in ("abco_envs", "abco_data", "abco_train"):
        shutil.copytree(REPO / package, tmp_path / package,
                        ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    before = source_digest(tmp_path)
    target = tmp_path / "abco_train" / "harness" / "metrics.py"
    text = target.read_text()
    target.write_text(text.replace('"""The paper\'s metrics', '"""Edited: the paper\'s metrics'))
    assert source_digest(tmp_path) == before  # a docstring edit
    report = tmp_path / "abco_train" / "report" / "write.py"
    report.write_text(report.read_text() + "\nEXTRA = 1\n")
    assert source_digest(tmp_path) == before  # the report never changes a number
    target.write_text(text + "\nEXTRA = 1\n")
    assert source_digest(tmp_path) != before  # code that trains or evaluates


def test_an_undefined_score_is_shown_as_a_dash():
    """A step cap no expert finishes within leaves the score undefined (``None``), never a
    crash of the run's table."""
    block = {"performance": 0.5, "aer": 1.0, "success_rate": 0.0, "episodes": 2, "score": None}
    table = format_table({"env": "MountainCar-v0", "method": "bco", "seed": 0,
                          "episodes": block, "headline": "episodes"})  # fmt: skip
    assert table.splitlines()[2].split()[:2] == ["episodes", "-"]
