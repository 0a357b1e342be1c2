"""What a newcomer meets first: the help, the default run folders, the end-of-run table, a
mistyped dataset path, the metrics plot."""

from __future__ import annotations

import subprocess
import sys

from train_testing import one_error_line

from abco_train.cli import build_parser, main
from abco_train.config.run import RunConfig, default_run_name
from abco_train.harness.evaluation import format_table
from abco_train.harness.plots import _visible_range
from abco_train.methods.registry import available, method_names


def _train_help() -> str:
    return build_parser()._subparsers._group_actions[0].choices["train"].format_help()


def test_the_help_lists_every_method_and_one_default_per_option() -> None:
    text = " ".join(_train_help().split()).replace("- ", "-")  # words wrapped at hyphens
    part = text.split("--method METHOD a registered method", 1)[1].split("--seed SEED", 1)[0]
    assert all(name in part for name in available()), part  # every registered method
    assert set(method_names()) >= set(available())
    options = _train_help().split("\n  --")[1:]
    assert len(options) > 30 and not [o for o in options if o.count("(default") > 1]


def test_a_plugins_method_is_in_the_help(tmp_path) -> None:
    plugin = tmp_path / "knn_plugin.py"
    plugin.write_text("from abco_train.methods import register\n"
                      "from abco_train.methods.reference import RandomReference\n"
                      "register('knn-ifo')(type('Knn', (RandomReference,), {}))\n")
    code = ("import sys; from abco_train.cli import main; "
            f"sys.exit(main(['train', '--plugin', {str(plugin)!r}, '--help']))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout
    text = " ".join(out.split()).replace("- ", "-")
    assert "knn-ifo" in text.split("--method METHOD a registered method", 1)[1].split("--seed")[0]


def test_default_run_folders_do_not_collide_across_presets_and_regimes() -> None:
    def folder(**kw):
        return RunConfig(env="AbcoMaze5x5-v0", **kw).resolved().run_dir

    main_job, paper = folder(), folder(preset="paper")
    assert main_job == "runs/AbcoMaze5x5-v0-abco-s0" and paper != main_job
    assert len({main_job, paper, folder(regime="authors"), folder(preset="general")}) == 4
    user_env = default_run_name(RunConfig(env="corridor:Corridor-v0", method="bco"))
    assert user_env == "corridor_Corridor-v0-bco-s0"


def test_a_missing_dataset_path_says_no_such_file_and_leaves_no_folder(tmp_path, capsys):
    run_dir = tmp_path / "run"
    code = main(["train", "--env", "CartPole-v1", "--method", "bco", "--quiet",
                 "--expert-data", "data/nope.hdf5", "--run-dir", str(run_dir)])  # fmt: skip
    assert code == 2
    one_error_line(capsys.readouterr().err, "no such file: data/nope.hdf5", "--expert-data")
    assert not run_dir.exists()


def test_a_run_refused_after_its_folder_was_made_leaves_none(tiny_data, tmp_path, capsys):
    """Data of the wrong kind is found out once the run holds its folder: the folder goes."""
    expert, pre = tiny_data("CartPole-v1")
    run_dir = tmp_path / "run"
    code = main(["train", "--env", "CartPole-v1", "--method", "bco", "--quiet",
                 "--expert-data", pre, "--pre-data", pre, "--run-dir", str(run_dir)])
    assert code != 0 and capsys.readouterr().err.startswith("error: ")
    assert not run_dir.exists()


def test_the_end_of_run_table_explains_itself() -> None:
    block = {"score": -0.588, "performance": -0.598, "aer": -0.818, "success_rate": 0.64,
             "episodes": 100}
    final = {"env": "AbcoMaze5x5-v0", "method": "abco", "seed": 0, "headline": "train/paper",
             "train/paper": {**block, "score": 1.0}, "test/standard": block}
    table = format_table(final)
    assert "score: 0 = a uniform random policy, 1 = the expert" in table
    assert "* train/paper: the block this run is ranked by." in table
    assert "standard: the env's own rules" in table  # why a score can be negative there
    final["test/standard"] = {**block, "score": 0.5}
    assert "standard: the env's own rules" not in format_table(final)


def test_a_flat_curve_is_drawn_flat() -> None:
    low, high = _visible_range([0.9951, 0.9958])
    assert high - low >= 0.1 and low < 0.9951 and high > 0.9958
    assert _visible_range([0.2, 0.9]) == (0.165, 0.935)
