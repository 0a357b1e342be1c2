"""Recording datasets of the user's own: abco_data.record and ``abco data record``."""

from __future__ import annotations

import re
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import abco_data
from abco_data import cli
from abco_data.errors import InvalidParameterError

SMALL = {"reference_episodes": 2, "reference_expert_episodes": 1, "progress": False}


def balance(obs):
    """A CartPole expert on one observation: push towards where the pole falls."""
    return int(3 * obs[2] + obs[3] > 0)


class TinyEnv(gym.Env):
    """Episodes of 5 steps with any observation and action space: for the space checks, and
    ``uint8`` image frames that depend on the step and the action."""

    def __init__(self, observation_space=None, action_space=None):
        self.observation_space = observation_space or spaces.Box(0, 255, (6, 8, 3), np.uint8)
        self.action_space = action_space or spaces.Discrete(3)
        self.t = 0

    def _obs(self, action=0):
        if isinstance(self.observation_space, spaces.Box) \
                and self.observation_space.dtype == np.uint8:
            frame = np.zeros(self.observation_space.shape, np.uint8)
            frame[self.t % 6, :, action % 3] = 200
            return frame
        return self.observation_space.sample()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        return self._obs(int(np.asarray(action).flat[0])), 1.0, self.t >= 5, False, {}


def _register(env_id, **kwargs):
    if env_id not in gym.registry:
        gym.register(env_id, entry_point=lambda **kw: TinyEnv(**kwargs, **kw),
                     max_episode_steps=20)
    return env_id


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch):
    """A data home (and user manifest) of each test's own."""
    monkeypatch.setenv("ABCO_DATA_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def test_expert_recording_is_abco_data_with_the_policy_actions_apart(tmp_path):
    path = abco_data.record("CartPole-v1", balance, kind="expert", episodes=2, seed=3,
                            id="local/pole-expert-v0", max_episode_steps=60, **SMALL)
    ds = abco_data.check_dataset("local/pole-expert-v0", kind="expert", env_id="CartPole-v1")
    assert ds.path == path and ds.id == "local/pole-expert-v0" and ds.num_episodes == 2
    arrays = ds.load_arrays()
    assert arrays.actions is None  # expert data: no training actions
    assert len(arrays.observations) == ds.num_transitions + ds.num_episodes  # T + 1 each
    obs_t, _ = ds.transition_index()
    expected = [balance(o) for o in arrays.observations[obs_t]]
    np.testing.assert_array_equal(ds.actions_of_transitions(idm_eval=True), expected)
    assert list(arrays.episode_seeds) == [3, 4]
    assert ds.reference.expert_mean == 60 > ds.reference.random_mean  # the cap, the policy
    assert '"policy":"test_record:balance"' in ds.attrs["creation_params"]
    assert ds.attrs["env_kwargs"] == '{"max_episode_steps":60}'


def test_pre_demonstrations_by_transitions_are_deterministic(tmp_path):
    first = abco_data.record("CartPole-v1", kind="pre", transitions=123, seed=5,
                             out=tmp_path / "a" / "walks.hdf5", **SMALL)
    again = abco_data.record("CartPole-v1", kind="pre", transitions=123, seed=5,
                             out=tmp_path / "b" / "walks.hdf5", **SMALL)
    ds = abco_data.open_dataset(first)
    assert ds.num_transitions == 123 and ds.kind == "pre_demonstrations"
    assert ds.id == "local/walks-v0"  # --out alone: an id of the file name, not registered
    assert len(ds.actions_of_transitions()) == 123
    assert abco_data.sha256_of(first) == abco_data.sha256_of(again)
    assert abco_data.verify(first).checksum == ""  # not registered: nothing to check against


def test_image_observations_from_a_module_env_id(tmp_path, monkeypatch):
    # A module that registers its env when imported, as gymnasium's ``module:Id`` expects.
    (tmp_path / "tiny_envs.py").write_text(textwrap.dedent("""
        import gymnasium as gym
        if "TinyImage-v0" not in gym.registry:
            gym.register("TinyImage-v0", entry_point="test_record:TinyEnv",
                         max_episode_steps=20)
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    path = abco_data.record("tiny_envs:TinyImage-v0", kind="pre", episodes=3,
                            out=tmp_path / "img.hdf5", **SMALL)
    ds = abco_data.check_dataset(path, kind="pre_demonstrations", env_id="TinyImage-v0")
    assert ds.env_id == "TinyImage-v0" and ds.observation_space.shape == (6, 8, 3)
    episode = ds.episode(0)
    actions = episode.actions
    assert actions is not None
    assert episode.observations.dtype == np.uint8 and len(episode.observations) == 6
    for t, a in enumerate(actions):  # frame t + 1 lights row t + 1 in colour a
        assert episode.observations[t + 1][(t + 1) % 6, 0, a] == 200


@pytest.mark.parametrize(("obs_space", "act_space", "hint"), [
    (spaces.Dict({"x": spaces.Box(0, 1, (2,))}), spaces.Discrete(2), "FlattenObservation"),
    (spaces.Box(0, 1, (3,)), spaces.Box(-1, 1, (1,)), "DiscretizeAction"),
    (spaces.Box(0, 1, (3, 3)), spaces.Discrete(2), "Box(0.0, 1.0, (3, 3), float32)"),
    (spaces.Box(0, 1, (3,)), spaces.Discrete(2, start=1), "Discrete(2, start=1)"),
])
def test_unsupported_spaces_are_refused_in_one_line(tmp_path, capsys, obs_space, act_space,
                                                    hint):
    env_id = _register(f"TinySpaces{abs(hash((str(obs_space), str(act_space))))}-v0",
                       observation_space=obs_space, action_space=act_space)
    with pytest.raises(InvalidParameterError, match=re.escape(hint)):
        abco_data.record(env_id, kind="pre", episodes=1, out=tmp_path / "x.hdf5", **SMALL)
    assert cli.main(["record", "--env", env_id, "--kind", "pre", "--episodes", "1",
                     "--out", str(tmp_path / "x.hdf5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and hint in err and err.count("\n") == 1
    assert not (tmp_path / "x.hdf5").exists()


def test_bad_arguments_are_refused_before_any_work(tmp_path):
    out = tmp_path / "x.hdf5"
    cases = [
        (dict(kind="expert", episodes=1), "needs the expert's policy"),
        (dict(kind="pre", episodes=0), "episodes=0 is out of range"),
        (dict(kind="pre", episodes=1, transitions=5), "either episodes or transitions"),
        (dict(kind="pre_demos", episodes=1), "unknown dataset kind"),
        (dict(kind="pre", episodes=1, seed=-1), "seed=-1"),
        (dict(kind="pre", episodes=100_000), "more than the 10,000,000"),
    ]
    for kwargs, message in cases:
        with pytest.raises(InvalidParameterError, match=message):
            abco_data.record("CartPole-v1", out=out, **{**SMALL, **kwargs})
    with pytest.raises(InvalidParameterError, match="have datasets of their own"):
        abco_data.record("AbcoMaze3x3-v0", kind="pre", episodes=1, out=out, **SMALL)
    with pytest.raises(InvalidParameterError, match="cannot make env 'NoSuchEnv-v0'"):
        abco_data.record("NoSuchEnv-v0", kind="pre", episodes=1, out=out, **SMALL)
    with pytest.raises(InvalidParameterError, match="returned 2, not an action"):
        abco_data.record("CartPole-v1", lambda obs: 2, kind="expert", episodes=1, out=out,
                         **SMALL)
    assert not out.exists()


def test_an_env_without_a_step_limit_needs_one(tmp_path):
    env_id = "TinyUnlimited-v0"
    if env_id not in gym.registry:
        gym.register(env_id, entry_point=lambda **kwargs: TinyEnv(**kwargs))
    with pytest.raises(InvalidParameterError, match="has no step limit"):
        abco_data.record(env_id, kind="pre", episodes=2, out=tmp_path / "x.hdf5", **SMALL)
    path = abco_data.record(env_id, kind="pre", episodes=2, out=tmp_path / "x.hdf5",
                            max_episode_steps=3, **SMALL)
    assert abco_data.open_dataset(path).num_transitions == 6  # truncated at 3 steps


def test_cli_record_with_a_policy_file_and_a_dotted_module(tmp_path, capsys, monkeypatch):
    assert cli.main(["record", "--env", "CartPole-v1", "--policy", f"{__file__}:balance",
                     "--kind", "expert", "--episodes", "2", "--id", "local/cli-v0",
                     "--max-episode-steps", "30", "--reference-episodes", "2",
                     "--reference-expert-episodes", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("local/cli-v0: wrote ") and "registered in" in out
    assert abco_data.load("local/cli-v0").reference.expert_mean == 30
    (tmp_path / "my_policies.py").write_text("def left(obs):\n    return 0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert cli.main(["record", "--env", "CartPole-v1", "--policy", "my_policies:left",
                     "--kind", "expert", "--transitions", "40", "--out",
                     str(tmp_path / "left.hdf5"), "--reference-episodes", "1",
                     "--reference-expert-episodes", "1", "--quiet"]) == 0
    actions = abco_data.open_dataset(tmp_path / "left.hdf5").actions_of_transitions(idm_eval=True)
    assert len(actions) == 40 and not actions.any()
    for policy, message in (("my_policies:right", "has no right"),
                            ("no_such_module_here:f", "failed to import"),
                            ("nocolon", "expected MODULE:CALLABLE")):
        assert cli.main(["record", "--env", "CartPole-v1", "--policy", policy, "--kind",
                         "expert", "--episodes", "1", "--out", str(tmp_path / "y.hdf5")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1


def test_a_stable_baselines3_model(tmp_path):
    sb3 = pytest.importorskip("stable_baselines3")
    model = sb3.DQN("MlpPolicy", "CartPole-v1", seed=0, device="cpu")
    model.save(tmp_path / "dqn.zip")
    path = abco_data.record("CartPole-v1", str(tmp_path / "dqn.zip"), kind="expert",
                            episodes=1, out=tmp_path / "dqn.hdf5", max_episode_steps=20, **SMALL)
    ds = abco_data.open_dataset(path)
    obs_t, _ = ds.transition_index()
    observations = ds.load_arrays().observations[obs_t]
    expected = [int(model.predict(o, deterministic=True)[0]) for o in observations]
    np.testing.assert_array_equal(ds.actions_of_transitions(idm_eval=True), expected)
    with pytest.raises(InvalidParameterError, match="unknown Stable-Baselines3 algorithm"):
        abco_data.record("CartPole-v1", str(tmp_path / "dqn.zip"), sb3_algo="NOPE",
                         kind="expert", episodes=1, out=tmp_path / "x.hdf5", **SMALL)
