"""Training that cannot fail silently: the IDM's held-out health, early stopping, the dead-IDM
rule, equal budgets across variants, Torabi's BCO(alpha), the authors' regime."""

from __future__ import annotations

import json

import numpy as np
import pytest
from train_testing import tiny_config

import abco_data
from abco_train.bench import grid
from abco_train.config.run import RunConfig
from abco_train.harness.loop import train
from abco_train.methods.bco import family as abco_module
from abco_train.methods.bco import idm as idm_module
from abco_train.methods.bco.fitting import validation_split
from abco_train.methods.registry import resolve_config
from abco_train.networks.builders import build_networks
from abco_train.report import write as report


def _metrics(run_dir) -> list[dict]:
    return [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]


def test_validation_split_is_fixed_and_disjoint() -> None:
    a_train, a_held = validation_split(5_000, None, seed=3)
    b_train, b_held = validation_split(5_000, None, seed=3)
    assert np.array_equal(a_held, b_held) and len(a_held) == 500
    assert len(np.intersect1d(a_train, a_held)) == 0 and len(a_train) + len(a_held) == 5_000
    assert len(validation_split(100_000, None, seed=0)[1]) == 2_000  # the cap
    assert not np.array_equal(validation_split(5_000, None, seed=4)[1], a_held)


def test_every_iteration_logs_the_idm_held_out_accuracy(tiny_data, tmp_path) -> None:
    train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "run", idm_epochs=3,
                      plots=True))  # fmt: skip
    for record in _metrics(tmp_path / "run"):
        stats = record["train"]
        assert 0.0 <= stats["idm_val_accuracy"] <= 1.0
        assert len(stats["idm_val_class_accuracy"]) == 2 and 1 <= stats["idm_epochs"] <= 3
        assert 0.5 <= stats["idm_chance"] <= 1.0
    assert (tmp_path / "run" / "metrics.png").exists()


def test_idm_stops_when_held_out_accuracy_stops_improving(tiny_data, tmp_path, monkeypatch):
    monkeypatch.setattr(abco_module.BCOFamily, "validate_idm",
                        lambda self: {"accuracy": 0.9, "class_accuracy": [0.9, 0.9]})
    train(tiny_config("CartPole-v1", "bco", tiny_data, tmp_path / "run", idm_epochs=6,
                      idm_patience=2))  # fmt: skip
    assert _metrics(tmp_path / "run")[0]["train"]["idm_epochs"] == 3  # 1 better + 2 stale


def test_an_idm_at_chance_is_reported_and_the_run_goes_on(tiny_data, tmp_path, monkeypatch,
                                                           capsys) -> None:  # fmt: skip
    """Algorithm 1 has no health stop: the run ends with its policy and a score; the check is
    logged per iteration, summed up in final.json and counted by the grid as a finished run."""
    calls = []

    def dead(self):
        calls.append(1)
        return {"accuracy": 0.0, "class_accuracy": [0.0, 0.0]}

    monkeypatch.setattr(abco_module.BCOFamily, "validate_idm", dead)
    monkeypatch.setattr(idm_module, "MIN_JUDGED", 0)
    cfg = tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "run")
    final = train(cfg)
    assert final["status"] == "ok" and np.isfinite(final["episodes"]["score"])
    assert final["health"]["idm_at_chance"] == [0, 1]  # both iterations flagged, both ran
    history = _metrics(tmp_path / "run")
    assert [h["train"]["idm_at_chance"] for h in history] == [True, True]
    assert all(h["train"]["idm_reinitialised"] == 0 for h in history)  # not by default
    assert all(0.0 <= h["train"]["idm_train_accuracy"] <= 1.0 for h in history)
    assert all(0.0 <= h["train"]["expert_label_entropy"] <= 1.0 for h in history)
    row = grid.result_row({"env": "CartPole-v1", "method": "abco", "seed": 0,
                           "run_dir": cfg.run_dir}, final, 1.0)  # fmt: skip
    assert row["status"] == "done"
    runs = report.Run("CartPole-v1", "abco", 0, tmp_path / "run", final)
    assert runs.status == "ok" and runs.values("episodes", "performance") is not None
    # with --idm-reinit, an IDM at chance is re-initialised and trained once more
    calls.clear()
    train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "again",
                      method_options={"idm_reinit": True}))
    again = _metrics(tmp_path / "again")
    assert [h["train"]["idm_reinitialised"] for h in again] == [1, 1]
    assert len(calls) >= 4  # trained, judged, re-initialised, trained again, judged again


def test_one_iteration_variants_get_the_same_policy_epochs(tiny_data, tmp_path) -> None:
    kw = {"iterations": 2, "policy_epochs": 2, "first_epochs_factor": 3}
    train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "abco", **kw))
    train(tiny_config("CartPole-v1", "bc", tiny_data, tmp_path / "bc", **kw))
    iterated = sum(r["train"]["policy_epochs"] for r in _metrics(tmp_path / "abco"))
    assert iterated == 2 * (3 + 2) == _metrics(tmp_path / "bc")[0]["train"]["policy_epochs"]


def test_torabi_bco_alpha_keeps_i_pre_and_adds_every_post_demonstration(tiny_data, tmp_path):
    train(tiny_config("AbcoMaze3x3-v0", "bco-alpha-torabi", tiny_data, tmp_path / "t",
                      iterations=2))  # fmt: skip
    rows = _metrics(tmp_path / "t")
    sizes = [r["train"]["idm_samples"] for r in rows]
    assert sizes[1] == rows[0]["post"]["is_from_pre"] + rows[0]["post"]["pos_transitions"]
    assert rows[1]["post"]["is_from_pre"] == rows[0]["post"]["is_from_pre"]  # I_pre stays
    assert rows[1]["post"]["pos_transitions"] > rows[0]["post"]["pos_transitions"]  # grows
    assert sizes[2] > sizes[1]


def test_the_authors_regime() -> None:
    cfg = resolve_config(RunConfig(env="AbcoMaze5x5-v0", regime="authors"))
    opts = cfg.method_options
    assert (cfg.pre_data, opts["idm_epochs"], opts["policy_epochs"], opts["first_epochs_factor"],
            cfg.iterations) == ("abco/maze5x5-pre-start-v0", 1, 1, 1, 10)
    assert RunConfig(env="AbcoMaze5x5-v0").resolved().pre_data is None
    spec = abco_data.spec("abco/maze5x5-pre-start-v0")
    assert spec.params["drop_wall_hits"] and spec.params["from_start_cell"]


def test_start_cell_pre_demonstrations_start_at_the_start_and_never_hit_a_wall(tmp_path):
    path = abco_data.generate("abco/maze3x3-pre-start-v0", tmp_path / "s.hdf5", progress=False,
                              layouts=3, episodes_per_layout=3, reference_episodes=2)
    ds = abco_data.open_dataset(path)
    for episode in ds.episodes():
        assert tuple(episode.positions[0]) == (0, 0)
        assert np.all(np.any(episode.positions[1:] != episode.positions[:-1], axis=1))


@pytest.mark.parametrize(("idm_input", "channels"), [("difference", 6), ("pair", 3)])
def test_image_idm_input(idm_input, channels) -> None:
    from gymnasium import spaces

    space = spaces.Box(0, 255, (64, 64, 3), np.uint8)
    _, idm = build_networks(space, 4, "cnn", True, idm_input)
    assert idm.encoder.body[0].in_channels == channels
    frames = np.random.default_rng(0).integers(0, 256, (2, 2, 64, 64, 3), dtype=np.uint8)
    import torch

    assert idm(torch.from_numpy(frames[0]), torch.from_numpy(frames[1])).shape == (2, 4)


def test_same_seed_same_maze_run(tiny_data, tmp_path) -> None:
    runs = [train(tiny_config("AbcoMaze3x3-v0", "abco", tiny_data, tmp_path / d)) for d in "ab"]
    strip = lambda rows: [{k: v for k, v in r.items() if not k.startswith("seconds")}  # noqa: E731
                          for r in rows]  # fmt: skip
    assert strip(_metrics(tmp_path / "a")) == strip(_metrics(tmp_path / "b"))
    assert runs[0]["train/paper"] == runs[1]["train/paper"]
