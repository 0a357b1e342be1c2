"""Issue 13's generalisation protocol: ``--layouts K``, fresh layouts, the ``general`` preset's
network and transpose augmentation, ``abco bench --layouts`` and the report's section.

Datasets are tiny procedural ones (8 layouts, never the real 10,000), generated once.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces
from train_testing import tiny_config

import abco_data
import abco_envs
from abco_data.registry import PROCEDURAL_ENVS
from abco_envs.maze.layout import layout_hash
from abco_envs.maze.render import MazeRenderer
from abco_envs.maze.rules import OPEN_E, OPEN_N, OPEN_S, OPEN_W
from abco_train.bench import grid as bench
from abco_train.cli import main as abco_main
from abco_train.config import run as config_module
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.evaluation import FRESH_SEED
from abco_train.harness.loop import train
from abco_train.harness.trained_policy import load_policy
from abco_train.harness.training_data import TRAIN_EVAL_LAYOUTS, load_training_data
from abco_train.methods.bco.fitting import TRANSPOSED_ACTIONS, fit, transpose_batch
from abco_train.methods.registry import config_from_record, resolve_config
from abco_train.networks.cells import CellReadout, cell_centres
from abco_train.report.runs import load_runs
from abco_train.report.write import write_report

LAYOUTS = 8
ENV = "AbcoMaze5x5-v0"
FRAMES = spaces.Box(0, 255, (64, 64, 3), np.uint8)


@pytest.fixture(scope="module")
def procedural(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    """Tiny 5x5 procedural expert and pre-demonstration files (the first 8 layouts)."""
    root = tmp_path_factory.mktemp("procedural")
    paths = []
    for kind, extra in (("expert", {}), ("pre", {"max_steps": 5})):
        dataset_id = f"abco/maze5x5-procedural-{kind}-v0"
        paths.append(str(abco_data.generate(
            dataset_id, root / f"{kind}.hdf5", progress=False, layouts=LAYOUTS,
            reference_episodes=2, **extra)))  # fmt: skip
    return paths[0], paths[1]


def _config(procedural: tuple[str, str], run_dir: Path, **changes: Any) -> RunConfig:
    expert, pre = procedural
    return tiny_config(ENV, changes.pop("method", "bc"), lambda env: (expert, pre), run_dir,
                       layouts=5, eval_layouts=3, **changes)  # fmt: skip


def _scores(final: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in final.items() if isinstance(v, dict) and "performance" in v}


# -- config: --layouts, presets, bad inputs -----------------------------------------------------


def test_layouts_selects_the_procedural_datasets() -> None:
    assert config_module.PROCEDURAL_ENVS == PROCEDURAL_ENVS
    cfg = RunConfig(env="AbcoMaze10x10-v0", layouts=100).resolved()
    assert (cfg.expert_data, cfg.pre_data) == ("abco/maze10x10-procedural-expert-v0",
                                               "abco/maze10x10-procedural-pre-v0")
    assert cfg.run_dir.endswith("AbcoMaze10x10-v0-abco-K100-s0")
    given = RunConfig(env=ENV, layouts=5, expert_data="mine.hdf5").resolved()
    assert given.expert_data == "mine.hdf5"  # named datasets win
    assert given.pre_data == "abco/maze5x5-procedural-pre-v0"
    plain = RunConfig(env=ENV).resolved()  # existing runs: nothing new is set
    assert (plain.layouts, plain.eval_fresh, plain.expert_data) == (None,) * 3
    assert resolve_config(plain).method_options["augment"] is None
    assert config_module.fresh_evaluation(plain) is False
    assert config_module.fresh_evaluation(given) is True
    assert config_module.fresh_evaluation(plain.replace(eval_fresh=True)) is True


def test_the_general_preset() -> None:
    cfg = resolve_config(RunConfig(env=ENV, preset="general"))
    opts = cfg.method_options
    assert (cfg.arch, opts["augment"], opts["idm_input"], cfg.attention, opts["min_updates"],
            opts["max_updates"]) == ("cellplan", "transpose", "difference", True, 1000, 1000)
    for preset in ("cpu", "paper"):  # the existing presets' defaults do not change
        old = resolve_config(RunConfig(env=ENV, preset=preset))
        assert [old.method_options[k] for k in ("augment", "min_updates", "max_updates")] == \
            [None] * 3
        assert old.arch in ("cnn", "resnet18")


@pytest.mark.parametrize(("changes", "message"), [
    ({"env": "AbcoMaze3x3-v0", "layouts": 5}, "--layouts needs a maze with procedural datasets"
     r" \(AbcoMaze5x5-v0 or AbcoMaze10x10-v0\), got --env AbcoMaze3x3-v0 \(a 3x3 grid"),
    ({"env": "CartPole-v1", "layouts": 5}, "--layouts needs a maze .* got --env CartPole-v1"),
    ({"layouts": 10_001}, r"--layouts must be <= 10,000 \(the layouts of the procedural"),
    ({"layouts": 0}, "--layouts must be >= 1, got 0"),
    ({"layouts": 5, "regime": "authors"}, "--regime authors brings its own pre-demonstrations"),
    ({"arch": "cellnet", "idm_input": "pair"}, "--arch cellnet reads a transition as one frame"),
    ({"env": "CartPole-v1", "augment": "transpose"}, "--augment transpose is for maze frames"),
    ({"env": "CartPole-v1", "eval_fresh": True}, "--eval-fresh is for mazes"),
    ({"env": "CartPole-v1", "arch": "cellnet"}, "--arch cellnet does not fit"),
    ({"augment": "flip"}, "--augment must be one of none, transpose"),
    ({"min_updates": 20, "max_updates": 10}, "--min-updates 20 is above --max-updates 10"),
])  # fmt: skip
def test_bad_settings_are_named(changes: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        resolve_config(config_from_record({"env": ENV, **changes}))


def test_general_preset_is_for_mazes_only() -> None:
    with pytest.raises(ConfigError, match="--preset general is not for CartPole-v1; use cpu or"
                                          " paper"):  # fmt: skip
        RunConfig(env="CartPole-v1", preset="general").resolved()


def test_bad_layouts_on_the_command_line(procedural, tmp_path, capsys) -> None:
    assert abco_main(["train", "--env", "AbcoMaze3x3-v0", "--layouts", "5", "--quiet"]) == 2
    assert "--layouts needs a maze" in capsys.readouterr().err
    expert, pre = procedural  # more layouts than the dataset holds: named, before training
    args = ["train", "--env", ENV, "--layouts", "9", "--expert-data", expert, "--pre-data", pre,
            "--run-dir", str(tmp_path / "run"), "--quiet", "--no-plots"]
    assert abco_main(args) == 2
    err = capsys.readouterr().err
    assert "--layouts 9 with --expert-data" in err and "has 8 layouts; take from 1 to 8" in err
    assert abco_main(["bench", "--envs", ENV, "--methods", "bc", "--layouts", "100,1e3",
                      "--out", str(tmp_path / "grid"), "--quiet"]) == 2  # fmt: skip
    assert "bad --layouts value '1e3'" in capsys.readouterr().err


# -- data: the first K layouts ----------------------------------------------------------------


def test_layouts_trains_on_exactly_the_first_k_layouts(procedural, tmp_path) -> None:
    expert, pre = procedural
    data = load_training_data(_config(procedural, tmp_path).resolved())
    for path, obs, rows in ((expert, data.expert_obs, data.expert_t),
                            (pre, data.pre_obs, data.pre_t)):  # fmt: skip
        view = abco_data.open_dataset(path).first_layouts(5)
        arrays = view.load_arrays()
        assert set(arrays.layout_indices.tolist()) == set(range(5))
        assert len(rows) == view.num_transitions < abco_data.open_dataset(path).num_transitions
        np.testing.assert_array_equal(obs, arrays.observations)
    assert data.layouts == 5
    np.testing.assert_array_equal(data.train_layouts, abco_envs.procedural_layouts(5, 5))
    # their references: computed for the training layouts, the pool's kept as they were
    ids = [layout_hash(c) for c in data.train_layouts]
    assert all(i in data.reference.layout_ids for i in ids)
    assert data.reference.layout_splits[-5:] == ("training",) * 5
    assert data.reference.layout_ids[:200] == abco_data.open_dataset(expert).reference.layout_ids
    assert TRAIN_EVAL_LAYOUTS == 100


# -- evaluation: fresh layouts -------------------------------------------------------------------


def test_fresh_reference_is_public_and_deterministic() -> None:
    ref = abco_data.fresh_reference(5, 4, seed=7, episodes=5)
    cells = abco_envs.fresh_layouts(5, 4, seed=7)
    assert ref.layout_ids == tuple(layout_hash(c) for c in cells)
    assert ref.layout_splits == ("fresh",) * 4
    again = abco_data.layout_reference(cells, "fresh", episodes=5, stream=8)
    np.testing.assert_array_equal(ref.random_per_layout, again.random_per_layout)
    assert (ref.expert_per_layout > ref.random_per_layout).all()
    with pytest.raises(ValueError, match="stack of k >= 1 layouts"):
        abco_data.layout_reference(np.zeros((0, 5, 5), np.uint8))


def test_fresh_evaluation_keys_and_determinism(procedural, tmp_path) -> None:
    final = train(_config(procedural, tmp_path / "run", plots=True, plot_layouts=2))
    keys = set(_scores(final))
    assert keys == {f"{s}/{p}" for s in ("train", "test", "fresh")
                    for p in ("paper", "standard")}  # fmt: skip
    assert final["layouts"] == 5
    assert final["fresh_layouts"] == {"count": 3, "seed": FRESH_SEED}
    assert all(final[k]["episodes"] == 3 for k in keys)
    assert {"paths_train", "paths_test", "paths_fresh"} <= set(final["figures"])
    # the same run again, from its folder: every number back
    again = load_policy(tmp_path / "run").evaluate()
    assert _scores(again) == _scores(final)


def test_fresh_layouts_are_the_same_for_every_run(procedural, tmp_path) -> None:
    """Two seeds and two methods roll out on the same fresh layouts (their ids)."""
    from abco_train.harness.rollouts import rollout

    cells = abco_envs.fresh_layouts(5, 3, FRESH_SEED)
    roll = rollout(lambda obs: np.zeros(len(obs), np.int64), ENV, layouts=cells, seed=5)
    assert roll.layout_ids == [layout_hash(c) for c in cells]
    assert roll.layout_indices.tolist() == [-1, -1, -1]
    a = train(_config(procedural, tmp_path / "a", seed=1))
    b = train(_config(procedural, tmp_path / "b", seed=2, method="bco"))
    assert a["fresh/paper"]["episodes"] == b["fresh/paper"]["episodes"] == 3


def test_eval_fresh_leaves_the_other_numbers_alone(tiny_data, tmp_path) -> None:
    base = tiny_config(ENV, "bc", tiny_data, tmp_path / "plain")
    plain = train(base)
    assert not any(k.startswith("fresh") for k in plain) and "layouts" not in plain
    fresh = train(base.replace(run_dir=str(tmp_path / "fresh"), eval_fresh=True))
    assert {k: v for k, v in _scores(fresh).items() if not k.startswith("fresh")} == \
        _scores(plain)
    assert fresh["fresh/paper"]["episodes"] == 2


# -- the general preset: the network and transposed mazes -------------------------------------


def test_readout_does_not_depend_on_where_features_lie() -> None:
    torch.manual_seed(0)
    readout = CellReadout(8, 6)
    x, h = torch.randn(2, 8, 5, 5), torch.randn(2, 6, 5, 5)
    perm = torch.randperm(25)

    def shuffle(t: torch.Tensor) -> torch.Tensor:
        return t.flatten(2)[:, :, perm].reshape(t.shape)

    torch.testing.assert_close(readout(x, h), readout(shuffle(x), shuffle(h)))
    assert readout(x, h).shape == (2, 12)


@pytest.mark.parametrize("n", [5, 10])
def test_cell_centres_are_the_renderers(n: int) -> None:
    renderer = MazeRenderer(n, 64, 64)
    centres = cell_centres(n, 64, 64)[0]
    for r, c in ((0, 0), (n - 1, n - 1), (1, n - 2)):
        y, x = renderer.cell_centre(r, c)  # pixel indices -> [-1, 1] over the image
        assert centres[r, c].tolist() == pytest.approx([(2 * x + 1) / 64 - 1,
                                                        (2 * y + 1) / 64 - 1])


def _transposed(cells: np.ndarray) -> np.ndarray:
    swap = {OPEN_N: OPEN_W, OPEN_W: OPEN_N, OPEN_E: OPEN_S, OPEN_S: OPEN_E}
    out = np.zeros_like(cells.T)
    for bit, other in swap.items():
        out |= np.where(cells.T & bit, other, 0).astype(cells.dtype)
    return out


def test_transposing_a_maze_maps_n_to_w_and_s_to_e() -> None:
    """The env itself: a transposed layout renders as the transposed frame, and each action
    of the original is TRANSPOSED_ACTIONS[action] in the transposed maze."""
    assert TRANSPOSED_ACTIONS.tolist() == [abco_envs.Action.W, abco_envs.Action.E,
                                           abco_envs.Action.S, abco_envs.Action.N]
    env, mirror = gym.make(ENV), gym.make(ENV)
    rng = np.random.default_rng(0)
    for cells in abco_envs.procedural_layouts(5, 4):
        obs, _ = env.reset(options={"layout": cells})
        other, _ = mirror.reset(options={"layout": _transposed(cells)})
        np.testing.assert_array_equal(obs.transpose(1, 0, 2), other)
        for action in rng.integers(4, size=30):
            obs, reward, done, _, info = env.step(int(action))
            other, reward2, done2, _, info2 = mirror.step(int(TRANSPOSED_ACTIONS[action]))
            np.testing.assert_array_equal(obs.transpose(1, 0, 2), other)
            assert (reward, done) == (reward2, done2)
            assert tuple(info["position"][::-1]) == tuple(info2["position"])
            if done:
                break


def test_transpose_batch() -> None:
    frames = torch.arange(4 * 3 * 3 * 1, dtype=torch.uint8).reshape(4, 3, 3, 1)
    labels = torch.tensor([0, 1, 2, 3])
    rng = np.random.default_rng(1)
    flip = np.random.default_rng(1).random(4) < 0.5
    (out,), mapped = transpose_batch([frames], labels, rng)
    for i in range(4):
        expect = frames[i].transpose(0, 1) if flip[i] else frames[i]
        assert torch.equal(out[i], expect)
        assert mapped[i] == (TRANSPOSED_ACTIONS[labels[i]] if flip[i] else labels[i])
    assert torch.equal(frames, torch.arange(36, dtype=torch.uint8).reshape(4, 3, 3, 1))


def test_min_updates_raises_epochs_on_small_data(procedural, tmp_path) -> None:
    """5 layouts are one minibatch an epoch: 10 updates take 10 epochs, times BC's budget."""
    train(_config(procedural, tmp_path / "run", min_updates=10))
    record = json.loads((tmp_path / "run" / "metrics.jsonl").read_text().splitlines()[0])
    assert record["train"]["policy_epochs"] == 10 * (1 + 1)  # first_epochs_factor + alpha


def test_max_updates_cuts_policy_units_on_large_data(procedural, tmp_path) -> None:
    """Batches of 4: an epoch of the 5 layouts' expert pairs is many updates; a unit is cut to
    3, BC's budget is two units (first_epochs_factor + alpha), so 6 updates in one epoch."""
    train(_config(procedural, tmp_path / "run", batch_size=4, policy_epochs=2, max_updates=3))
    record = json.loads((tmp_path / "run" / "metrics.jsonl").read_text().splitlines()[0])
    assert (record["train"]["policy_updates"], record["train"]["policy_epochs"]) == (6, 1)


def test_fit_stops_after_max_batches() -> None:
    net = torch.nn.Linear(3, 2)
    steps = []
    opt = torch.optim.SGD(net.parameters(), lr=0.1)
    opt.register_step_post_hook(lambda *_: steps.append(1))
    x, y = torch.randn(10, 3), torch.randint(0, 2, (10,))
    fit(net, opt, lambda idx: (x[idx],), y, 3, 4, np.random.default_rng(0), max_batches=5)
    assert len(steps) == 5  # 3 epochs of 3 batches would be 9
    fit(net, opt, lambda idx: (x[idx],), y, 2, 4, np.random.default_rng(0))
    assert len(steps) == 5 + 6


def test_general_preset_trains_both_networks(procedural, tmp_path) -> None:
    final = train(_config(procedural, tmp_path / "run", method="abco", preset="general",
                          min_updates=1))  # fmt: skip
    assert final["status"] == "ok" and "fresh/paper" in final
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert (config["arch"], config["method_options"]["augment"], config["layouts"]) == \
        ("cellplan", "transpose", 5)


# -- the grid and the report ---------------------------------------------------------------------


def test_bench_cells_per_number_of_layouts(tmp_path) -> None:
    cells = bench.plan([ENV], ["bc"], [0], layouts=[100, 1000])
    assert [c.key for c in cells] == [f"{ENV}/bc/layouts100/seed0", f"{ENV}/bc/layouts1000/seed0"]
    assert cells[1].run_dir(tmp_path) == tmp_path / ENV / "bc" / "layouts1000" / "seed0"
    assert bench.cell_config(cells[0], tmp_path)["layouts"] == 100
    assert "layouts" not in bench.cell_config(bench.Cell(ENV, "bc", 0), tmp_path)
    assert bench.parse_layouts("100, 1000,100") == [100, 1000]
    with pytest.raises(ConfigError, match="the grid sets layouts per cell"):
        bench.cell_config(cells[0], tmp_path, {"layouts": 5})


def test_bench_runs_a_layouts_grid(procedural, tmp_path) -> None:
    expert, pre = procedural
    out = tmp_path / "grid"
    args = ["bench", "--envs", ENV, "--methods", "bc", "--seeds", "0", "--layouts", "2,4",
            "--out", str(out), "--expert-data", expert, "--pre-data", pre, "--quiet",
            "--jobs", "1", "--threads", "1", "--policy-epochs", "1", "--first-epochs-factor",
            "1", "--iterations", "1", "--eval-layouts", "2", "--eval-max-steps", "20",
            "--no-plots"]  # fmt: skip
    assert abco_main(args) == 0
    rows = bench.read_results(out)
    assert set(rows) == {f"{ENV}/bc/layouts2/seed0", f"{ENV}/bc/layouts4/seed0"}
    assert rows[f"{ENV}/bc/layouts4/seed0"]["layouts"] == 4
    assert json.loads((out / ENV / "bc" / "layouts2" / "seed0" / "final.json").read_text()
                      )["layouts"] == 2  # fmt: skip
    assert abco_main(args) == 0  # finished cells are skipped
    assert '"skipped": 2' in (out / bench.BENCH_LOG).read_text().splitlines()[-1]
    runs = load_runs(out)
    assert sorted((r.layouts, r.status, bool(r.row)) for r in runs) == [(2, "ok", True),
                                                                       (4, "ok", True)]
    files = write_report(out)
    md = files["report"].read_text()
    assert "## Generalisation" in md and "## Table 1" not in md
    assert files["generalisation"].exists()


def _fake(root: Path, env: str, method: str, seed: int, layouts: int | None,
          p: float, success: float) -> None:  # fmt: skip
    run_dir = root / env / method / ("" if layouts is None else f"layouts{layouts}") / f"seed{seed}"
    run_dir.mkdir(parents=True)
    final: dict[str, Any] = {"env": env, "method": method, "seed": seed, "status": "ok"}
    for k, split in enumerate(("train", "test", "fresh")):
        if layouts is None and split == "fresh":
            continue
        q = p - 0.1 * k
        final[f"{split}/paper"] = {"performance": q, "aer": q, "success_rate": success,
                                   "episodes": 2, "episode_performance": [q - 0.01, q + 0.01],
                                   "episode_returns": [q, q]}  # fmt: skip
    if layouts is not None:
        final["layouts"] = layouts
    (run_dir / "final.json").write_text(json.dumps(final))


def test_report_generalisation_table_and_plot(tmp_path) -> None:
    root = tmp_path / "runs"
    for method, gain in (("bc", 0.0), ("abco", 0.05)):
        for seed in range(3):
            _fake(root, ENV, method, seed, None, 0.5 + gain, 0.5)
            for k in (100, 1000, 10_000):
                _fake(root, ENV, method, seed, k, 0.4 + gain + 0.1 * np.log10(k), 0.25 * (seed + 1))
    _fake(root, "CartPole-v1", "bc", 0, None, 1.0, 1.0)  # no layouts: not in the section
    files = write_report(root, tmp_path / "report")
    md = files["report"].read_text()
    section = md.split("## Generalisation", 1)[1].split("\n## ", 1)[0]
    rows = [x for x in section.splitlines() if x.startswith(f"| {ENV} |")]
    assert [r.split(" | ")[1:3] for r in rows] == [
        [label, k] for label in ("BC", "ABCO(α)") for k in ("standard", "100", "1,000", "10,000")]
    bc_1000 = next(r for r in rows if r.startswith(f"| {ENV} | BC | 1,000 |")).split(" | ")
    assert bc_1000[3] == "seeds 0-2"
    assert bc_1000[4].startswith("0.700 [") and bc_1000[5] == "0.50"  # train P, success
    assert bc_1000[6].startswith("0.600 [") and bc_1000[8].startswith("0.500 [")  # test, fresh
    standard = next(r for r in rows if r.startswith(f"| {ENV} | BC | standard |")).split(" | ")
    assert standard[-2:] == ["–", "– |"]  # not evaluated on fresh layouts
    # the paper's tables keep the standard-data runs only
    table1 = md.split("## Table 1 re-measured", 1)[1].split("\n## ", 1)[0]
    assert f"| {ENV} | BC | 3 |" in table1
    assert files["generalisation"].name == "generalisation.png"
    assert files["generalisation"].stat().st_size > 10_000
    import csv

    with files["csv"].open() as f:
        gen = [r for r in csv.DictReader(f) if r["table"] == "generalisation"]
    fresh = [r for r in gen if r["evaluation"] == "fresh/paper" and r["metric"] == "success_rate"
             and r["method"] == "abco" and r["layouts"] == "10000"]  # fmt: skip
    assert len(fresh) == 1 and float(fresh[0]["mean"]) == pytest.approx(0.5)
    assert {r["layouts"] for r in gen} == {"", "100", "1000", "10000"}


def test_success_rate_is_one_number_per_run(tmp_path) -> None:
    """A run's success rate is its own number, never its episodes' P."""
    _fake(tmp_path, ENV, "bc", 0, 100, 0.9, 0.25)
    run = load_runs(tmp_path)[0]
    assert run.values("test/paper", "success_rate").tolist() == [0.25]
    assert len(run.values("test/paper", "performance")) == 2


def test_generalisation_plot_keeps_one_colour_per_method_across_envs(tmp_path, monkeypatch) -> None:
    """A maze that has only some methods' runs draws them in the colours of the other rows."""
    import matplotlib.pyplot as plt

    from abco_train.report.plots import plot_generalisation

    class Runs:
        def __init__(self, success: float) -> None:
            self.success = success

        def values(self, evaluation: str, metric: str) -> list[float]:
            return [self.success, self.success]

    cells = {(ENV, "bc", 100): [Runs(0.5)], (ENV, "abco", 100): [Runs(0.6)],
             ("AbcoMaze10x10-v0", "abco", 10_000): [Runs(0.7)]}  # fmt: skip
    figures = []
    monkeypatch.setattr(plt, "close", figures.append)  # keep the figure to look at it
    assert plot_generalisation(cells, tmp_path / "g.png") is not None
    colours: dict[str, set[str]] = {}
    for ax in figures[0].axes:
        for bars in ax.containers:
            method = bars.get_label().split(",")[0]
            colours.setdefault(method, set()).add(bars.lines[0].get_color())
        assert ax.get_xlim()[0] < 100 and ax.get_xlim()[1] > 10_000  # one x range for all rows
    assert set(colours) == {"bc", "abco"}
    assert all(len(c) == 1 for c in colours.values()) and colours["bc"] != colours["abco"]
