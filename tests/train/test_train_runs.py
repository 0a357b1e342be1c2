"""End-to-end tests of the trainer on tiny datasets: every variant on all six envs, resuming,
the CLI, evaluation rollouts."""

from __future__ import annotations

import json

import numpy as np
import pytest
from train_testing import tiny_config

import abco_envs
from abco_train.harness.loop import train
from abco_train.harness.rollouts import rollout, score
from abco_train.methods.bco.family import VARIANTS

ENVS = (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS)


@pytest.mark.parametrize("env_id", ENVS)
def test_every_variant_runs_end_to_end(env_id, tiny_data, tmp_path):
    for method in VARIANTS:
        plots = method == "abco" and env_id in ("AbcoMaze3x3-v0", "CartPole-v1")
        cfg = tiny_config(env_id, method, tiny_data, tmp_path / method, plots=plots)
        final = train(cfg)
        keys = ("train/paper", "train/standard", "test/paper", "test/standard") \
            if env_id in abco_envs.MAZE_IDS else ("episodes",)
        for key in keys:
            assert np.isfinite(final[key]["performance"]), (method, key)
        lines = (tmp_path / method / "metrics.jsonl").read_text().splitlines()
        assert len(lines) == (2 if VARIANTS[method]["iterative"] else 1)
        for fig in final["figures"].values():
            assert (tmp_path / method / fig.split("/")[-1]).exists()
        if plots:
            assert {"metrics", "labels"} <= set(final["figures"])


def test_resume_continues_exactly_where_it_stopped(tiny_data, tmp_path):
    env = "AbcoMaze3x3-v0"
    full = train(tiny_config(env, "abco", tiny_data, tmp_path / "full", iterations=2))
    cfg = tiny_config(env, "abco", tiny_data, tmp_path / "cut", iterations=2)
    assert train(cfg, stop_after=1) is None
    assert len((tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()) == 1
    resumed = train(cfg)

    def evals(folder):
        rows = [json.loads(x) for x in (folder / "metrics.jsonl").read_text().splitlines()]
        return [(r["iteration"], r["eval"], r["train"], r["label_distribution"]) for r in rows]

    assert evals(tmp_path / "full") == evals(tmp_path / "cut")
    drop = ("figures", "seconds")
    assert {k: v for k, v in full.items() if k not in drop} == \
        {k: v for k, v in resumed.items() if k not in drop}
    with pytest.raises(ValueError, match="another config"):
        train(tiny_config(env, "abco", tiny_data, tmp_path / "cut", iterations=3, seed=1))


def test_same_seed_same_run(tiny_data, tmp_path):
    a = train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "a"))
    b = train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "b"))
    assert a["episodes"] == b["episodes"]
    ra = (tmp_path / "a" / "metrics.jsonl").read_text().splitlines()
    rb = (tmp_path / "b" / "metrics.jsonl").read_text().splitlines()
    strip = lambda r: {k: v for k, v in json.loads(r).items() if not k.startswith("seconds")}  # noqa: E731
    assert [strip(r) for r in ra] == [strip(r) for r in rb]


def test_cli_train_and_data_commands(tiny_data, tmp_path, capsys):
    from abco_train.cli import main

    expert, pre = tiny_data("CartPole-v1")
    code = main(["train", "--env", "CartPole-v1", "--method", "bco", "--idm-epochs", "1",
                 "--eval-max-steps", "50",
                 "--policy-epochs", "1", "--eval-episodes", "2", "--expert-data", expert,
                 "--pre-data", pre, "--run-dir", str(tmp_path / "cli"), "--quiet"])
    out = capsys.readouterr().out
    assert code == 0 and "bco on CartPole-v1" in out and "plot metrics" in out
    config = json.loads((tmp_path / "cli" / "config.json").read_text())
    assert config["method_options"]["idm_epochs"] == 1
    assert main(["data", "list"]) == 0
    assert "abco/maze5x5-expert-v0" in capsys.readouterr().out


# -- evaluation ----------------------------------------------------------------------------------


def _expert_from_state(n):
    """A batched maze expert that reads position and walls from state observations."""
    from abco_envs.experts import MazeExpert
    from abco_envs.maze.layout import OPEN_BITS

    def act(obs):
        actions = []
        for o in obs:
            row, col = int(np.argmax(o[:n])), int(np.argmax(o[n:2 * n]))
            bits = o[2 * n:].reshape(n, n, 4) > 0.5
            cells = (bits * OPEN_BITS).sum(-1).astype(np.uint8)
            actions.append(MazeExpert(cells, seed=0).act(row, col))
        return np.array(actions)

    return act


def test_maze_evaluation_on_all_layouts_batched():
    from abco_data.generation.reference import maze_reference

    calls = []

    def expert(obs):
        calls.append(len(obs))
        return _expert_from_state(3)(obs)

    roll = rollout(expert, "AbcoMaze3x3-v0", env_kwargs={"obs_type": "state"}, split="test")
    assert len(roll.returns) == 100 and roll.successes.all()
    assert len(calls) == roll.lengths.max()  # one forward pass per step for all episodes
    assert calls[0] == 100
    m = score(roll, maze_reference(3, episodes=5))
    assert m["performance"] == pytest.approx(1.0)


def test_paper_protocol_ends_at_the_fourth_visit():
    stuck = lambda obs: np.zeros(len(obs), dtype=np.int64)  # noqa: E731  (N: a wall at start)
    paper = rollout(stuck, "AbcoMaze3x3-v0", episodes=4, protocol="paper")
    assert paper.lengths.tolist() == [3] * 4 and paper.returns.tolist() == [-1.0] * 4
    standard = rollout(stuck, "AbcoMaze3x3-v0", episodes=2, protocol="standard")
    assert standard.lengths.tolist() == [1000, 1000]
    assert standard.returns == pytest.approx([-1000 * 0.1 / 9] * 2)


def test_post_demonstrations_are_recorded_per_run():
    rng = np.random.default_rng(0)
    roll = rollout(lambda o: rng.integers(2, size=len(o)), "CartPole-v1", episodes=3,
                   record=True)
    assert len(roll.actions) == roll.lengths.sum()
    assert len(roll.observations) == roll.lengths.sum() + 3
    assert np.bincount(roll.run_ids).tolist() == roll.lengths.tolist()
    assert (roll.successes == (roll.lengths >= 195)).all()


def test_paper_preset_trains_the_resnet(tiny_data, tmp_path):
    cfg = tiny_config("AbcoMaze3x3-v0", "abco", tiny_data, tmp_path / "paper", preset="paper",
                      iterations=0, eval_layouts=1)
    assert cfg.resolved().arch == "resnet18"
    final = train(cfg)
    assert np.isfinite(final["train/paper"]["performance"])


def test_a_plugged_in_method_is_trained_and_evaluated_by_the_harness(tiny_data, tmp_path):
    from abco_train.methods import Method, available, register

    @register("test-constant")
    class Constant(Method):
        """Always the most common expert action: the harness must not care what it is."""

        def train_iteration(self, iteration):
            self.action = int(np.bincount(self.data.expert_eval_actions).argmax())
            self.seen = getattr(self, "seen", 0)
            return {"action": self.action}

        def act(self, obs):
            return np.full(len(obs), self.action)

        def observe(self, iteration, rollouts):
            self.seen += len(rollouts.returns)
            return {"seen": self.seen}

        def state_dict(self):
            return {"action": self.action, "seen": self.seen}

        def load_state_dict(self, state):
            self.action, self.seen = state["action"], state["seen"]

    assert "test-constant" in available()
    final = train(tiny_config("CartPole-v1", "test-constant", tiny_data, tmp_path / "c"))
    rows = [json.loads(x) for x in (tmp_path / "c" / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == 2 and rows[-1]["post"]["seen"] == 4
    assert final["episodes"]["episodes"] == 2


def test_cli_reports_bad_input_without_a_traceback(tmp_path, capsys):
    from abco_train.cli import main

    assert main(["train", "--env", "Nope-v0", "--quiet"]) == 2
    assert "unknown env id 'Nope-v0'" in capsys.readouterr().err
    bad = tmp_path / "bad.hdf5"
    bad.write_bytes(b"not an hdf5 file")
    code = main(["train", "--env", "CartPole-v1", "--expert-data", str(bad), "--quiet",
                 "--run-dir", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2 and str(bad) in err and "corrupt" in err
