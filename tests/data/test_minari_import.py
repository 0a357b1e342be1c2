"""Minari import through Minari's public API: abco -> Minari -> abco round trips, and Minari
datasets made here without reference scores or with spaces abco does not store."""

from __future__ import annotations

import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_data import cli
from abco_data.errors import (
    CorruptDatasetError,
    DatasetError,
    InvalidParameterError,
    UnknownDatasetError,
)

minari = pytest.importorskip("minari")
from minari.data_collector import EpisodeBuffer  # noqa: E402

from abco_data.interop.minari_export import export_to_minari  # noqa: E402
from abco_data.interop.minari_import import import_minari  # noqa: E402


@pytest.fixture(autouse=True)
def homes(tmp_path, monkeypatch):
    """A data home and a Minari datasets root of each test's own."""
    monkeypatch.setenv("ABCO_DATA_HOME", str(tmp_path / "home"))
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))


@pytest.mark.parametrize("dataset_id", ["abco/cartpole-expert-v0", "abco/acrobot-pre-v0"])
def test_round_trip_through_minari_keeps_every_column(tmp_path, dataset_id):
    original = abco_data.open_dataset(make_small(dataset_id, tmp_path))
    export_to_minari(original)
    kind = "expert" if original.kind == "expert" else "pre"
    path = import_minari(dataset_id, id="local/round-trip-v0", kind=kind, progress=False)
    back = abco_data.check_dataset("local/round-trip-v0", kind=original.kind,
                                   env_id=original.env_id)
    assert back.path == path and back.env_id == original.env_id
    a, b = original.load_arrays(), back.load_arrays()
    np.testing.assert_array_equal(b.observations, a.observations)
    for column in ("actions", "idm_eval_actions", "rewards", "terminations", "truncations",
                   "episode_lengths", "episode_seeds", "episode_returns"):
        np.testing.assert_array_equal(getattr(b, column), getattr(a, column), err_msg=column)
    # Minari's ref_min_score / ref_max_score are the exported references.
    assert (back.reference.random_mean, back.reference.expert_mean) == (
        original.reference.random_mean, original.reference.expert_mean)
    # At once usable as a run's data.
    from abco_train.harness.training_data import resolve_dataset

    assert resolve_dataset(str(path), original.env_id, original.kind).id == back.id


def _buffers(env, episodes, last_cut=False):
    """CartPole episodes of a fixed policy as Minari episode buffers (the last one cut short,
    neither terminated nor truncated, with ``last_cut``)."""
    out = []
    for i in range(episodes):
        obs, _ = env.reset(seed=100 + i)
        observations, actions, rewards, terms, truncs = [obs], [], [], [], []
        done = False
        while not done:
            action = int(3 * obs[2] + obs[3] > 0)
            obs, reward, terminated, truncated, _ = env.step(action)
            observations.append(obs)
            actions.append(action)
            rewards.append(reward)
            terms.append(terminated)
            truncs.append(truncated)
            done = terminated or truncated or len(actions) == 30
        if last_cut and i == episodes - 1:
            terms[-1] = truncs[-1] = False
        # Minari annotates these as lists; its storage takes arrays (as abco's export does).
        columns: dict = {"observations": np.array(observations), "actions": np.array(actions),
                         "rewards": np.array(rewards), "terminations": np.array(terms),
                         "truncations": np.array(truncs)}
        out.append(EpisodeBuffer(id=i, seed=100 + i, **columns))
    return out


def _create(minari_id, env, buffers, **extra):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return minari.create_dataset_from_buffers(minari_id, buffers, env=env.spec,
                                                  algorithm_name="test", **extra)


def test_references_measured_where_minari_has_none(tmp_path, capsys):
    env = gym.make("CartPole-v1", max_episode_steps=30)  # the recorded env: 30 steps
    _create("test/pole-v0", env, _buffers(env, 3, last_cut=True))
    path = import_minari("test/pole-v0", out=tmp_path / "pole.hdf5", reference_episodes=3,
                         progress=False)
    ds = abco_data.open_dataset(path)
    arrays = ds.load_arrays()
    # The expert reference: the mean return of the dataset's own episodes.
    assert ds.reference.expert_mean == pytest.approx(arrays.episode_returns.mean())
    assert ds.reference.expert_mean == 30  # the fixed policy balances for 30 steps
    assert 0 < ds.reference.random_mean < 30  # random actions, in the env recovered
    assert ds.attrs["env_kwargs"] == '{"max_episode_steps":30}'  # as it was recorded
    assert bool(arrays.truncations[-1]) and not arrays.terminations[-1]  # cut: truncated
    np.testing.assert_array_equal(arrays.episode_seeds, [100, 101, 102])
    # Deterministic: the same import gives the same bytes.
    again = import_minari("test/pole-v0", out=tmp_path / "again" / "pole.hdf5",
                          reference_episodes=3, progress=False)
    assert abco_data.sha256_of(again) == abco_data.sha256_of(path)
    assert cli.main(["import-minari", "test/pole-v0", "--id", "local/pole-v0", "--quiet",
                     "--reference-episodes", "2"]) == 0
    assert "registered in" in capsys.readouterr().out
    assert abco_data.load("local/pole-v0").num_episodes == 3


def test_what_abco_cannot_import_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    env = gym.make("MountainCarContinuous-v0")
    obs, _ = env.reset(seed=0)
    steps = [env.step(np.array([0.5], np.float32)) for _ in range(3)]
    columns: dict = {"observations": np.array([obs] + [s[0] for s in steps]),
                     "actions": np.full((3, 1), 0.5, np.float32),
                     "rewards": np.array([s[1] for s in steps]),
                     "terminations": np.array([False, False, False]),
                     "truncations": np.array([False, False, True])}
    buffer = EpisodeBuffer(id=0, **columns)
    _create("test/continuous-v0", env, [buffer])
    with pytest.raises(InvalidParameterError, match="Discrete actions from 0"):
        import_minari("test/continuous-v0", out=tmp_path / "x.hdf5", progress=False)
    with pytest.raises(UnknownDatasetError, match="no Minari dataset test/nothing-v0"):
        import_minari("test/nothing-v0", out=tmp_path / "x.hdf5", progress=False)
    assert cli.main(["import-minari", "test/nothing-v0", "--out", str(tmp_path / "x.hdf5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no Minari dataset" in err
    assert not (tmp_path / "x.hdf5").exists()
    monkeypatch.setitem(sys.modules, "minari", None)  # as if the extra were not installed
    with pytest.raises(DatasetError, match=r"pip install 'abco\[minari\]'"):
        import_minari("test/continuous-v0", out=tmp_path / "x.hdf5", progress=False)


def test_damaged_minari_data_is_reported_not_imported(tmp_path):
    env = gym.make("CartPole-v1")
    _create("test/damaged-v0", env, _buffers(env, 2))
    import h5py

    data = tmp_path / "minari" / "test" / "damaged-v0" / "data" / "main_data.hdf5"
    with h5py.File(data, "a") as f:
        del f["episode_1/rewards"]
    with pytest.raises(CorruptDatasetError, match="cannot read Minari dataset test/damaged-v0"):
        import_minari("test/damaged-v0", out=tmp_path / "x.hdf5", progress=False)
    assert not (tmp_path / "x.hdf5").exists()
