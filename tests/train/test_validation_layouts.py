"""Validation layouts: a run that chooses settings (``held_out="validation"``) is evaluated on
maze layouts disjoint from the test split, the test's fresh layouts and its own expert
episodes' layouts; a track's validation seeds get them, its test seeds the test's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_generalisation import _config, _scores, procedural  # noqa: F401  (a fixture)
from train_testing import tiny_config

import abco_envs
from abco_envs.maze.layout import layout_hash
from abco_envs.maze.pool import layout_pool
from abco_train.bench.cells import cell_config, plan_track
from abco_train.bench.tasks import load_track
from abco_train.config.run import ConfigError, RunConfig, evaluation_blocks
from abco_train.harness.evaluation import FRESH_LAYOUTS, FRESH_SEED, validation_layouts
from abco_train.harness.loop import train
from abco_train.harness.trained_policy import load_policy

MAZE3 = "AbcoMaze3x3-v0"


def _ids(layouts: np.ndarray) -> set[str]:
    return {layout_hash(c) for c in layouts}


def test_blocks_of_a_validation_run_hold_no_test_block() -> None:
    test = evaluation_blocks(RunConfig(env="AbcoMaze5x5-v0", layouts=10))
    val = evaluation_blocks(RunConfig(env="AbcoMaze5x5-v0", layouts=10, held_out="validation"))
    assert {"test/paper", "fresh/paper"} <= set(test)
    assert set(val) == {"train/paper", "train/standard", "validation/paper",
                        "validation/standard"}  # fmt: skip
    assert evaluation_blocks(RunConfig(env="CartPole-v1", held_out="validation")) == ("episodes",)
    with pytest.raises(ConfigError, match="--headline must be one of"):
        RunConfig(env=MAZE3, held_out="validation", headline="test/paper").validate()


def test_3x3_validation_layouts_are_train_layouts_no_expert_episode_plays() -> None:
    pool = layout_pool(3)
    shown = frozenset(pool.train_ids[:32])
    data = SimpleNamespace(expert_layout_ids=shown)
    layouts, source = validation_layouts(RunConfig(env=MAZE3, held_out="validation"), data)
    ids = _ids(layouts)
    assert source.startswith("train split") and len(layouts) == 68
    assert ids.isdisjoint(shown) and ids.isdisjoint(pool.test_ids)
    assert ids <= set(pool.train_ids)
    everything = SimpleNamespace(expert_layout_ids=frozenset(pool.train_ids))
    with pytest.raises(ConfigError, match="expert episodes play every layout"):
        validation_layouts(RunConfig(env=MAZE3, held_out="validation"), everything)


@pytest.mark.parametrize("layouts", [None, 10])
def test_5x5_validation_layouts_are_fresh_and_not_the_tests(layouts) -> None:
    """Tested on fresh layouts (``--layouts``) or with every train layout in the expert's
    episodes: fresh layouts of their own stream, none of the test's fresh ones."""
    pool = layout_pool(5)
    data = SimpleNamespace(expert_layout_ids=frozenset(pool.train_ids))
    cfg = RunConfig(env="AbcoMaze5x5-v0", layouts=layouts, held_out="validation")
    got, source = validation_layouts(cfg, data)
    assert source == "fresh" and len(got) == FRESH_LAYOUTS
    tested = _ids(abco_envs.fresh_layouts(5, FRESH_LAYOUTS, FRESH_SEED))
    assert _ids(got).isdisjoint(tested)
    assert _ids(got).isdisjoint(pool.train_ids + pool.test_ids)
    again, _ = validation_layouts(cfg, data)
    np.testing.assert_array_equal(got, again)


def test_a_validation_run_is_scored_on_validation_layouts(procedural, tmp_path) -> None:  # noqa: F811
    final = train(_config(procedural, tmp_path / "run", held_out="validation",
                          headline="validation/paper"))  # fmt: skip
    assert set(_scores(final)) == {"train/paper", "train/standard", "validation/paper",
                                   "validation/standard"}  # fmt: skip
    assert final["validation_layouts"] == {"count": 3, "source": "fresh"}
    assert final["headline"] == "validation/paper" and "fresh_layouts" not in final
    again = load_policy(tmp_path / "run").evaluate()
    assert _scores(again) == _scores(final)


def test_a_3x3_validation_run_plays_train_layouts_it_never_saw(tiny_data, tmp_path) -> None:
    cfg = tiny_config(MAZE3, "bc", tiny_data, tmp_path / "run", held_out="validation")
    final = train(cfg)  # the tiny datasets' expert plays a few of the train split's layouts
    assert final["validation_layouts"] == {"count": 2, "source": "train split, in no expert "
                                           "episode"}  # fmt: skip
    assert final["validation/paper"]["episodes"] == 2 and "test/paper" not in final


def test_track_validation_seeds_play_validation_layouts(tmp_path) -> None:
    track = load_track("headline")
    cells = plan_track(track, ["maze3x3-heldout", "maze5x5-heldout", "cartpole-authors-data"],
                       ["bc"], [100, 1000])  # fmt: skip
    got = {(c.task, c.seed): cell_config(c, tmp_path, track=track) for c in cells}
    assert got["maze3x3-heldout", 100]["headline"] == "validation/paper"
    assert got["maze5x5-heldout", 100]["headline"] == "validation/paper"
    assert got["maze3x3-heldout", 100]["held_out"] == "validation"
    assert got["maze3x3-heldout", 1000]["headline"] == "test/paper"
    assert got["maze5x5-heldout", 1000]["headline"] == "fresh/paper"
    assert "held_out" not in got["maze3x3-heldout", 1000]
    assert "held_out" not in got["cartpole-authors-data", 100]  # no layouts to hold out
    for cfg in got.values():
        RunConfig(**cfg).validate()
