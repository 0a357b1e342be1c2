"""abco train on envs of the user's own: any registered Gymnasium id, ``module:Id-v0`` included,
on datasets recorded with abco_data.record (user ids); spaces abco does not learn from refused
in one line; ``--success``."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from train_testing import one_error_line, tiny_config

import abco_data
from abco_envs.success import SuccessRule, success_rule
from abco_train.cli import main as abco_main
from abco_train.config.envs import env_spaces, parse_success, run_success_rule
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.loop import train
from abco_train.methods.registry import resolve_config

LENGTH = 6
#: ``--env`` of the test envs: this module, imported by Gymnasium, registers them.
VECTOR_ENV, IMAGE_ENV = "test_any_env:Corridor-v0", "test_any_env:CorridorImage-v0"
SMALL = {"reference_episodes": 5, "reference_expert_episodes": 3, "progress": False}
#: Every built-in method, with options that keep each run to seconds.
METHOD_OPTIONS = {
    "bc": {}, "bco": {}, "bco-alpha": {}, "bco-alpha-torabi": {}, "abco": {}, "iupe": {},
    "ilpo": {"train_steps": 4, "remap_steps": 24, "remap_envs": 4, "remap_epochs": 2},
    "gaifo": {"rl_steps": 64, "n_envs": 2, "n_steps": 16, "batch_size": 16, "n_epochs": 1,
              "d_batch_size": 16, "net_arch": [16]},
    "random": {}, "expert": {},
}  # fmt: skip


class Corridor(gym.Env):
    """Walk right to the end of a corridor of :data:`LENGTH` cells (reward 1 there, -0.1 a
    step before): the cell as a one-hot vector, or (``image``) a 3 x LENGTH x 3 ``uint8``
    frame with the agent's column lit. Actions: left, right, stay."""

    def __init__(self, image: bool = False, observation_space=None, action_space=None):
        self.image, self.pos = image, 0
        self.observation_space = observation_space or (
            spaces.Box(0, 255, (3, LENGTH, 3), np.uint8) if image
            else spaces.Box(0.0, 1.0, (LENGTH,), np.float32))  # fmt: skip
        self.action_space = action_space or spaces.Discrete(3)

    def _obs(self):
        if isinstance(self.observation_space, spaces.Dict):
            return self.observation_space.sample()
        if self.image:
            frame = np.zeros((3, LENGTH, 3), np.uint8)
            frame[:, self.pos, 1] = 7  # small values, as MiniGrid's symbolic cells
            return frame
        return np.eye(LENGTH, dtype=np.float32)[self.pos]

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = int(self.np_random.integers(0, LENGTH - 1))
        return self._obs(), {}

    def step(self, action):
        move = (-1, 1, 0)[int(np.asarray(action).reshape(-1)[0]) % 3]
        self.pos = min(max(self.pos + move, 0), LENGTH - 1)
        done = self.pos == LENGTH - 1
        return self._obs(), 1.0 if done else -0.1, done, False, {}


def right(obs):
    """The corridor's expert: always right."""
    return 1


def _register(env_id: str, **kwargs) -> None:
    if env_id not in gym.registry:
        gym.register(env_id, entry_point=lambda **kw: Corridor(**kwargs, **kw),
                     max_episode_steps=20)


_register("Corridor-v0")
_register("CorridorImage-v0", image=True)
_register("DictCorridor-v0", observation_space=spaces.Dict({"x": spaces.Box(0, 1, (2,))}))
_register("SlideCorridor-v0", action_space=spaces.Box(-1.0, 1.0, (1,)))


@pytest.fixture(scope="module")
def home(tmp_path_factory):
    """A data home holding the corridors' user datasets (recorded once)."""
    path = tmp_path_factory.mktemp("home")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ABCO_DATA_HOME", str(path))
        for env_id, name in ((VECTOR_ENV, "corridor"), (IMAGE_ENV, "corridor-image")):
            abco_data.record(env_id, right, kind="expert", episodes=12, seed=0,
                             id=f"local/{name}-expert-v0", **SMALL)
            abco_data.record(env_id, kind="pre", transitions=600, seed=1,
                             id=f"local/{name}-pre-v0", **SMALL)
        yield path


def _tiny(env_id: str, method: str, name: str, run_dir: Path, **changes) -> RunConfig:
    """A seconds-long run on the user datasets ``local/{name}-{expert,pre}-v0``."""
    changes = {"eval_episodes": 3, "device": "cpu", **changes}
    return tiny_config(env_id, method, lambda _: (f"local/{name}-expert-v0",
                                                  f"local/{name}-pre-v0"), run_dir,
                       eval_max_steps=None, **changes)  # fmt: skip


def _argv(env_id: str, name: str, run_dir: Path, *extra: str) -> list[str]:
    return ["train", "--env", env_id, "--expert-data", f"local/{name}-expert-v0",
            "--pre-data", f"local/{name}-pre-v0", "--run-dir", str(run_dir), "--iterations",
            "1", "--idm-epochs", "1", "--policy-epochs", "1", "--eval-episodes", "4",
            "--quiet", "--no-plots", "--threads", "1", *extra]


def test_a_module_env_trains_end_to_end_on_user_datasets(home, tmp_path, capsys):
    assert abco_main(_argv(VECTOR_ENV, "corridor", tmp_path / "run")) == 0
    final = json.loads((tmp_path / "run" / "final.json").read_text())
    expert = abco_data.load("local/corridor-expert-v0")
    block = final["episodes"]
    assert final["status"] == "ok" and final["env"] == VECTOR_ENV
    assert block["episodes"] == 4 and len(block["episode_scores"]) == 4
    # the score's references are the expert dataset's (its random and expert returns)
    returns = np.asarray(block["episode_returns"])
    expected = (returns - expert.reference.random_mean) / (
        expert.reference.expert_mean - expert.reference.random_mean)
    np.testing.assert_allclose(block["episode_scores"], expected)
    assert "score" in capsys.readouterr().out


def test_play_refuses_in_one_line_an_env_that_draws_no_frames(home, tmp_path, capsys):
    assert abco_main(_argv(VECTOR_ENV, "corridor", tmp_path / "run")) == 0
    capsys.readouterr()
    assert abco_main(["play", str(tmp_path / "run"), "--quiet"]) == 2
    one_error_line(capsys.readouterr().err, "does not render 'rgb_array'", "render modes: none")
    assert not (tmp_path / "run" / "play_train.gif").exists()


def test_the_encoder_follows_the_observations(home):
    vector = resolve_config(RunConfig(env=VECTOR_ENV, expert_data="x", pre_data="y"))
    image = resolve_config(RunConfig(env=IMAGE_ENV, expert_data="x", pre_data="y"))
    assert (vector.arch, image.arch) == ("mlp", "cnn")
    assert env_spaces(IMAGE_ENV).observation_shape == (3, LENGTH, 3)
    with pytest.raises(ConfigError, match="--arch mlp does not fit"):
        RunConfig(env=IMAGE_ENV, arch="mlp", expert_data="x", pre_data="y").validate()


@pytest.mark.parametrize("method", list(METHOD_OPTIONS))
def test_every_builtin_method_runs_on_a_user_env(home, tmp_path, method):
    cfg = _tiny(VECTOR_ENV, method, "corridor", tmp_path / method,
                method_options=METHOD_OPTIONS[method])
    final = train(cfg)
    assert final is not None and final["status"] == "ok", final
    assert np.isfinite(final["episodes"]["score"])
    if method == "expert":  # the policy that recorded the dataset, reloaded: always right
        assert final["episodes"]["success_rate"] == 1.0


@pytest.mark.parametrize("method", ["abco", "ilpo"])
def test_an_image_env_trains(home, tmp_path, method):
    options = {**METHOD_OPTIONS[method], **({"policy_steps": 4} if method == "ilpo" else {})}
    cfg = _tiny(IMAGE_ENV, method, "corridor-image", tmp_path / method, method_options=options)
    final = train(cfg)
    assert final is not None and final["status"] == "ok", final
    assert final["episodes"]["episodes"] == 3


@pytest.mark.filterwarnings("ignore:.*Taxi-v3 is out of date:DeprecationWarning")
@pytest.mark.parametrize(("env_id", "needles"), [
    ("Taxi-v4", ["Discrete(500)", "FlattenObservation", "one-hot"]),
    ("Taxi-v3", ["unknown env id 'Taxi-v3'", "Taxi-v4"]),
    ("test_any_env:DictCorridor-v0", ["Dict observations (x)", "ImgObsWrapper"]),
    ("test_any_env:SlideCorridor-v0", ["Box(-1.0, 1.0, (1,), float32)", "Discrete actions"]),
    ("Pendulum-v1", ["abco trains on Discrete actions", "DiscretizeAction"]),
    ("no_such_module_here:X-v0", ["unknown env id", "No module named"]),
])  # fmt: skip
def test_spaces_abco_does_not_learn_from_are_refused_in_one_line(tmp_path, capsys, env_id,
                                                                 needles):
    argv = ["train", "--env", env_id, "--expert-data", "a.hdf5", "--pre-data", "b.hdf5",
            "--run-dir", str(tmp_path / "run")]
    assert abco_main(argv) == 2
    one_error_line(capsys.readouterr().err, *needles)
    assert not (tmp_path / "run").exists()


def test_a_user_env_without_datasets_says_how_to_record_them(tmp_path, capsys):
    assert abco_main(["train", "--env", VECTOR_ENV, "--run-dir", str(tmp_path / "r")]) == 2
    one_error_line(capsys.readouterr().err, "has no built-in expert dataset",
                   f"abco data record --env {VECTOR_ENV} --kind expert", "--expert-data")


def test_a_damaged_user_dataset_fails_in_one_line_naming_the_file(tmp_path, capsys,
                                                                 monkeypatch):
    monkeypatch.setenv("ABCO_DATA_HOME", str(tmp_path / "home"))
    path = abco_data.record(VECTOR_ENV, right, kind="expert", episodes=3,
                            id="local/corridor-broken-v0", **SMALL)
    abco_data.record(VECTOR_ENV, kind="pre", transitions=100, id="local/corridor-walk-v0",
                     **SMALL)
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    argv = ["train", "--env", VECTOR_ENV, "--expert-data", "local/corridor-broken-v0",
            "--pre-data", "local/corridor-walk-v0", "--run-dir", str(tmp_path / "run"),
            "--quiet"]
    assert abco_main(argv) == 2
    one_error_line(capsys.readouterr().err, str(path), "do not match the user manifest")
    assert not (tmp_path / "run" / "final.json").exists()


def test_a_user_id_never_shadows_a_builtin_one(tmp_path, monkeypatch):
    monkeypatch.setenv("ABCO_DATA_HOME", str(tmp_path))
    with pytest.raises(abco_data.InvalidParameterError, match="abco's own"):
        abco_data.record("CartPole-v1", kind="pre", transitions=10,
                         id="abco/cartpole-pre-v0", **SMALL)
    # a user manifest edited by hand to claim a built-in id is not read for it: the run
    # looks for abco's own file in the cache
    mine = abco_data.record("CartPole-v1", kind="pre", transitions=10, out=tmp_path / "m.hdf5",
                            **SMALL)
    (tmp_path / "user-datasets.json").write_text(json.dumps({
        "format": "abco-user-datasets", "version": 1,
        "datasets": {"abco/cartpole-pre-v0": {
            "path": str(mine), "size": mine.stat().st_size, "sha256": abco_data.sha256_of(mine),
            "env_id": "CartPole-v1", "kind": "pre_demonstrations"}}}))
    from abco_train.harness.training_data import resolve_dataset

    with pytest.raises(abco_data.DatasetError) as err:
        resolve_dataset("abco/cartpole-pre-v0", "CartPole-v1", "pre_demonstrations",
                        cache_dir=str(tmp_path / "cache"), cached_only=True)
    assert "cartpole-pre-v0.hdf5" in str(err.value) and str(mine) not in str(err.value)


def test_success_rules():
    assert run_success_rule(VECTOR_ENV, None) == SuccessRule("terminated")  # the default
    assert run_success_rule("CartPole-v1", None) is None  # the table's
    assert run_success_rule("CartPole-v1", "steps>=100") == SuccessRule("steps", 100)
    assert parse_success(" return >= -1.5 ") == SuccessRule("return", -1.5)
    for bad in ("won", "steps>=0", "steps>=2.5", "return>=nan", "return>5"):
        with pytest.raises(ConfigError, match="--success"):
            parse_success(bad)
    with pytest.raises(ConfigError, match="--success must be terminated"):
        RunConfig(env="CartPole-v1", success="always").validate()


def test_success_follows_the_run_rule(home, tmp_path):
    # The expert walks 1 to 5 cells: 'steps>=4' counts only the longer walks
    finals = [train(_tiny(VECTOR_ENV, "expert", "corridor", tmp_path / str(rule),
                          eval_episodes=20, success=rule)) for rule in (None, "steps>=4")]
    rates = [f["episodes"]["success_rate"] for f in finals if f is not None]
    assert rates[0] == 1.0 and 0.0 < rates[1] < 1.0
    assert success_rule(VECTOR_ENV) == SuccessRule("steps", 4)  # the last run's, in this process


def test_bench_and_report_take_a_user_env(home, tmp_path, capsys):
    out = tmp_path / "grid"
    argv = ["bench", "--envs", VECTOR_ENV, "--methods", "bco,abco", "--seeds", "0",
            "--out", str(out), "--expert-data", "local/corridor-expert-v0", "--pre-data",
            "local/corridor-pre-v0", "--iterations", "1", "--idm-epochs", "1",
            "--policy-epochs", "1", "--eval-episodes", "3", "--threads", "1", "--jobs", "2",
            "--quiet"]  # fmt: skip
    assert abco_main(argv) == 0
    rows = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert {r["status"] for r in rows} == {"done"} and len(rows) == 2
    assert all(r["reference"]["expert"] > r["reference"]["random"] for r in rows)
    assert abco_main(["report", str(out)]) == 0
    report = (out / "report" / "report.md").read_text()
    found = report.split("## Every (env, method) found", 1)[1]  # beside any built-in env's
    for method in ("bco", "abco"):
        assert f"| {VECTOR_ENV} | {method} | 1 |" in found


def test_expert_refuses_in_one_line_a_policy_it_cannot_reload(home, tmp_path, capsys):
    abco_data.record(VECTOR_ENV, lambda obs: 1, kind="expert", episodes=2,
                     id="local/corridor-lambda-v0", **SMALL)
    argv = ["train", "--env", VECTOR_ENV, "--method", "expert", "--expert-data",
            "local/corridor-lambda-v0", "--pre-data", "local/corridor-pre-v0", "--run-dir",
            str(tmp_path / "run"), "--quiet"]
    assert abco_main(argv) == 2
    one_error_line(capsys.readouterr().err, "--method expert: cannot reload the policy",
                   "local/corridor-lambda-v0", "<lambda>")
