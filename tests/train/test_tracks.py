"""Benchmark tracks: the built-in headline track, track files and their refusals, the cells of
a track's grid and their configs, and ``abco bench --track`` end to end on a tiny track."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

import abco_envs
from abco_train.bench.cells import cell_config, plan_track
from abco_train.bench.tasks import MAX_TRACK_BYTES, load_track
from abco_train.cli import _bench_plan, build_parser
from abco_train.config.run import ConfigError, RunConfig

IFO = ("bco", "bco-alpha", "bco-alpha-torabi", "abco", "iupe", "ilpo", "gaifo")


def test_headline_track_covers_every_environment():
    track = load_track("headline")
    envs = [t.env for t in track.tasks]
    assert len(track.tasks) >= 7
    assert set(envs) == {*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS}
    assert {"random", "expert", "bc", *IFO} <= set(track.methods)
    assert track.validation_seeds and track.test_seeds
    for task in track.tasks:
        assert task.measures and task.basis, task.name
        cfg = RunConfig(**task.config()).validate()
        assert cfg.budget == task.budget and cfg.task == task.name


def test_headline_budgets_follow_one_rule():
    """budget = 10,000 x |A|, at most half of it as pre-demonstrations (the protocol's rule;
    Acrobot's task takes ten random episodes' worth, less)."""
    import gymnasium as gym

    for task in load_track("headline").tasks:
        if task.env in abco_envs.CLASSIC_IDS:
            env = gym.make(task.env)
            actions = int(env.action_space.n)  # type: ignore[attr-defined]
            env.close()
        else:
            actions = 4
        assert task.budget == 10_000 * actions, task.name
        assert 0 < task.settings["pre_transitions"] <= 5_000 * actions, task.name


def _write(tmp_path: Path, text: str) -> str:
    path = tmp_path / "track.toml"
    path.write_text(text)
    return str(path)


GOOD = """
[track]
name = "t"
methods = ["random", "bco"]
validation_seeds = "100"
[[task]]
name = "cp"
env = "CartPole-v1"
budget = 100
"""


@pytest.mark.parametrize("old, new, message", [
    ("budget = 100", "budget = 0", "needs a budget"),
    ("budget = 100", "budget = 100\nsettings = { colour = 1 }", "unknown key(s) 'colour'"),
    ("budget = 100", "budget = 100\nsettings = { seed = 1 }", "unknown key(s) 'seed'"),
    ("budget = 100", "budget = 100\nsettings = { batch_size = 0 }", "--batch-size must be"),
    ("budget = 100", "budget = 100\nheadline = 'test/paper'", "--headline must be one of"),
    ('env = "CartPole-v1"', 'env = "Pong-v9"', "unknown env id"),
    ('name = "cp"', 'name = "a/b"', "name"),
    ("budget = 100", "budget = 100\ncolour = 1", "unknown key(s) 'colour'"),
    ("[[task]]", "[[task]\n", "not a TOML file"),
    ("budget = 100", "budget = 100\nmethod_settings = { bco = { seed = 1 } }",
     "method_settings.bco has unknown key(s) 'seed'"),
    ("budget = 100", "budget = 100\nmethod_settings = { bco = { lr = -1.0 } }", "--lr"),
    ("budget = 100", "budget = 100\nmethod_settings = { bco = 1 }", "is not a table"),
    ("budget = 100", "budget = 100\nmethod_settings = { bcoo = { lr = 0.1 } }",
     "sets options of bcoo, not a method of the track"),
    ("budget = 100", "budget = 100\nmethod_options = { abco = { idm_epochs = 1 } }",
     "sets options of abco, not a method of the track"),
    ("budget = 100", "budget = 100\ntest_seeds = '5-2'", "task 'cp' test_seeds: "),
    ("budget = 100", "budget = 100\ntest_seeds = '99-100'", "100 are both validation and test"),
    ('validation_seeds = "100"', 'validation_seeds = "100"\ntest_seeds = "100-109"',
     "100 are both validation and test"),
])  # fmt: skip
def test_track_file_refusals(tmp_path, old, new, message):
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        load_track(path)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_missing_and_oversized_track_files(tmp_path):
    with pytest.raises(ConfigError, match="cannot read it"):
        load_track(tmp_path / "none.toml")
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * (MAX_TRACK_BYTES + 1))
    with pytest.raises(ConfigError, match="larger"):
        load_track(big)


def test_track_cells_and_their_configs(tmp_path):
    track = load_track(_write(tmp_path, GOOD + """
[task.method_options.bco]
idm_epochs = 3
"""))
    cells = plan_track(track, [], ["random", "bco"], [100, 101])
    assert [c.key for c in cells] == ["cp/random/seed100", "cp/random/seed101",
                                      "cp/bco/seed100", "cp/bco/seed101"]  # fmt: skip
    assert cells[0].ident == ("cp", "random", 100, None)
    cfg = cell_config(cells[2], tmp_path / "out", {"eval_episodes": 3}, track=track)
    assert (cfg["task"], cfg["budget"], cfg["env"], cfg["eval_episodes"]) == \
        ("cp", 100, "CartPole-v1", 3)  # fmt: skip
    assert cfg["method_options"] == {"idm_epochs": 3}
    assert cell_config(cells[0], tmp_path, track=track)["method_options"] == {}
    with pytest.raises(ConfigError, match="fixes budget"):
        cell_config(cells[0], tmp_path, {"budget": 5}, track=track)
    with pytest.raises(ConfigError, match="no task 'other'"):
        plan_track(track, ["other"], ["bco"], [0])


def test_a_task_may_have_test_seeds_of_its_own(tmp_path):
    """A costly task tests on fewer seeds than the track's (``--seeds test``); every other
    seed list (validation, given) is the same for every task."""
    path = _write(tmp_path, GOOD.replace('validation_seeds = "100"',
                                         'validation_seeds = "100"\ntest_seeds = "2000-2003"')
                  + '[[task]]\nname = "maze"\nenv = "AbcoMaze3x3-v0"\nbudget = 100\n'
                  'test_seeds = "2000-2001"\n')  # fmt: skip
    track = load_track(path)
    assert track.own_test_seeds() == {"maze": [2000, 2001]}
    assert track.all_test_seeds() == [2000, 2001, 2002, 2003]

    def keys(seeds: str) -> list[str]:
        args = build_parser().parse_args(["bench", "--track", path, "--out", "o",
                                          "--methods", "bco", "--seeds", seeds])  # fmt: skip
        return [cell.key for cell in _bench_plan(args)[1]]

    assert keys("test") == [*(f"cp/bco/seed{s}" for s in range(2000, 2004)),
                            "maze/bco/seed2000", "maze/bco/seed2001"]  # fmt: skip
    assert keys("validation") == ["cp/bco/seed100", "maze/bco/seed100"]
    assert keys("7") == ["cp/bco/seed7", "maze/bco/seed7"]
    # every task with seeds of its own: the track needs none
    path = _write(tmp_path, Path(path).read_text().replace('test_seeds = "2000-2003"',
                                                      'validation_seeds = "101"', 1)
                  .replace('validation_seeds = "100"\n', "", 1)
                  .replace('budget = 100\n', 'budget = 100\ntest_seeds = "7"\n', 1))
    assert keys("test") == ["cp/bco/seed7", "maze/bco/seed2000", "maze/bco/seed2001"]


def test_method_settings_apply_to_their_method_only(tmp_path):
    track = load_track(_write(tmp_path, GOOD + """settings = { lr = 0.003 }
[task.method_settings.bco]
lr = 0.001
"""))
    random_cell, bco_cell = plan_track(track, [], ["random", "bco"], [100])
    assert cell_config(bco_cell, tmp_path, track=track)["lr"] == 0.001
    assert cell_config(random_cell, tmp_path, track=track)["lr"] == 0.003
    with pytest.raises(ConfigError, match="fixes lr"):
        cell_config(bco_cell, tmp_path, {"lr": 0.1}, track=track)


def test_bench_runs_a_track(tmp_path):
    track = _write(tmp_path, GOOD.replace('methods = ["random", "bco"]',
                                          'methods = ["random", "expert"]'))  # fmt: skip
    out = tmp_path / "grid"
    run = subprocess.run(
        [sys.executable, "-m", "abco_train", "bench", "--track", track, "--out", str(out),
         "--eval-episodes", "3", "--quiet"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    finals = sorted(out.glob("cp/*/seed100/final.json"))
    assert [p.parts[-3] for p in finals] == ["expert", "random"]
    record = json.loads(finals[0].read_text())
    assert (record["task"], record["budget"], record["headline"]) == ("cp", 100, "episodes")
    both = subprocess.run(
        [sys.executable, "-m", "abco_train", "bench", "--track", track, "--envs",
         "CartPole-v1", "--out", str(out)], capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert both.returncode == 2 and "give --envs" in both.stderr
    curve = subprocess.run(
        [sys.executable, "-m", "abco_train", "bench", "--track", track, "--out", str(out),
         "--methods", "expert", "--budget-multiples", "4", "--eval-episodes", "3", "--quiet"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert curve.returncode == 0, curve.stderr
    record = json.loads((out / "cp@x4/expert/seed100/final.json").read_text())
    assert (record["task"], record["budget"]) == ("cp@x4", 400)


@pytest.mark.parametrize("flags, message", [
    (["--budget-multiples", "1"], "1 is not a multiple from 2 to 64"),
    (["--budget-multiples", "4x"], "'4x' is not a whole number"),
    (["--budget-multiples", "4", "--envs", "CartPole-v1"], "applies to a --track grid"),
])  # fmt: skip
def test_budget_multiples_refusals(tmp_path, flags, message):
    args = ["--track", "headline"] if "--envs" not in flags else []
    run = subprocess.run([sys.executable, "-m", "abco_train", "bench", *args, *flags, "--out",
                          str(tmp_path / "grid")], capture_output=True, text=True, timeout=600)
    assert run.returncode == 2 and message in run.stderr, run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "grid").exists()


def test_v1_budget_curves_are_the_headline_variants():
    """The v1 budget curves' track file holds what ``abco bench --budget-multiples 4,16``
    makes of its two headline tasks: each ``TASK@xM`` its task but for the budget and GAIfO's
    PPO steps (settings, per-method settings, every other option the same)."""
    from abco_train.bench.tasks import budget_variants
    from abco_train.report.budget_curves import variant_of

    root = Path(__file__).resolve().parents[2]
    headline = load_track("headline")
    curves = load_track(root / "docs/results/headline/budget-curves.toml")
    assert curves.test_seeds and set(curves.methods) == {"gaifo", "abco"}
    bases = sorted({variant_of(t.name)[0] for t in curves.tasks})  # type: ignore[index]
    assert bases == ["acrobot-ten-random-episodes", "lunarlander"]
    chosen = replace(headline, tasks=tuple(headline.task(b) for b in bases))
    made = budget_variants(chosen, [4, 16])
    assert [t.name for t in made.tasks] == [t.name for t in curves.tasks]
    for task in curves.tasks:
        want = made.task(task.name)
        assert (task.env, task.budget, task.headline, dict(task.settings)) == \
            (want.env, want.budget, want.headline, dict(want.settings)), task.name  # fmt: skip
        assert {m: dict(s) for m, s in task.method_settings.items()} == \
            {m: dict(s) for m, s in want.method_settings.items() if m in curves.methods}
        assert {m: dict(o) for m, o in task.method_options.items()} == \
            {m: dict(o) for m, o in want.method_options.items()}  # fmt: skip
        assert task.method_options["gaifo"]["rl_steps"] == task.budget


def test_budget_variants_scale_the_budget_only():
    from abco_train.bench.tasks import budget_variants

    headline = load_track("headline")
    made = budget_variants(headline, [4])
    assert len(made.tasks) == len(headline.tasks)
    for base, task in zip(headline.tasks, made.tasks):
        assert task.name == f"{base.name}@x4" and task.budget == 4 * base.budget
        assert task.settings == base.settings and task.method_settings == base.method_settings
        for method, options in base.method_options.items():  # only options at the budget
            assert task.method_options[method] == {
                k: 4 * v if v == base.budget else v for k, v in options.items()}
    with pytest.raises(ConfigError, match="65 is not a multiple from 2 to 64"):
        budget_variants(headline, [65])
    huge = replace(headline, tasks=(replace(headline.tasks[0], budget=10**9),))
    with pytest.raises(ConfigError, match="a run has at most 10,000,000,000"):
        budget_variants(huge, [16])


def test_every_method_of_a_headline_task_sees_the_same_inputs_and_encoder(tmp_path):
    """No input or encoder that one method has and another lacks on a task: one ``arch`` per
    task for every method, ILPO's cell target exactly where that encoder reads cells."""
    from abco_train.config.run import CELL_ARCHS, RunConfig
    from abco_train.methods.registry import resolve_config

    track = load_track("headline")
    for task in track.tasks:
        cells = plan_track(track, [task.name], track.methods, [1000])
        seen = {c.method: resolve_config(RunConfig(**cell_config(c, tmp_path, track=track)))
                for c in cells}  # fmt: skip
        archs = {cfg.arch for cfg in seen.values()}
        assert len(archs) == 1, (task.name, archs)
        cells = seen["ilpo"].method_options["target"] == "cells"
        assert cells == (archs.pop() in CELL_ARCHS), task.name
        assert len({cfg.pre_transitions for cfg in seen.values()}) == 1, task.name
