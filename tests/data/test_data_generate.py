"""Generation: contents of each dataset family, determinism, recorded parameters."""

import hashlib
import json

import h5py
import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_envs.maze.layout import shortest_path_length


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_maze_expert_is_optimal(tmp_path):
    ds = abco_data.open_dataset(make_small("abco/maze5x5-expert-v0", tmp_path))
    assert ds.num_episodes == 2 * 2 and ds.kind == "expert"
    for ep in ds.episodes():
        assert ep.actions is None
        assert ep.terminations[-1] and not ep.truncations.any()
        assert ep.length == shortest_path_length(ep.layout)
        assert ep.positions[0].tolist() == [0, 0] and ep.positions[-1].tolist() == [4, 4]
        assert len(ep.observations) == ep.length + 1
        assert ep.episode_return == pytest.approx(1 - (ep.length - 1) * 0.1 / 25)
        assert ep.layout_index == ep.index // 2


def test_maze_pre_demonstrations(tmp_path):
    ds = abco_data.open_dataset(make_small("abco/maze3x3-pre-v0", tmp_path))
    assert ds.kind == "pre_demonstrations"
    for ep in ds.episodes():
        assert ep.positions[0].tolist() != [2, 2]  # never starts on the goal
        assert 1 <= ep.length <= 6 and ep.actions is not None
        assert ep.terminations[-1] or ep.truncations[-1]


def test_drop_wall_hits(tmp_path):
    path = make_small("abco/maze3x3-pre-v0", tmp_path, drop_wall_hits=True)
    ds = abco_data.open_dataset(path)
    a = ds.load_arrays()
    obs_t, obs_t1 = ds.transition_index()
    moved = np.any(a.positions[obs_t] != a.positions[obs_t1], axis=1)
    assert moved.all()
    assert json.loads(ds.attrs["creation_params"])["drop_wall_hits"] is True


@pytest.mark.parametrize("dataset_id", [i for i in abco_data.DATASET_IDS if "maze" not in i])
def test_classic_datasets(tmp_path, dataset_id):
    path = make_small(dataset_id, tmp_path)
    report = abco_data.verify(path)
    ds = abco_data.open_dataset(path)
    assert report.num_transitions == ds.num_transitions > 0
    if ds.kind == "pre_demonstrations":
        assert ds.num_transitions == 300
    assert ds.reference.layout_ids is None
    assert ds.reference.expert_mean > ds.reference.random_mean


def test_held_action_pre_demonstrations(tmp_path):
    path = make_small("abco/acrobot-pre-held-v0", tmp_path)
    ds = abco_data.open_dataset(path)
    assert json.loads(ds.attrs["creation_params"])["hold"] == 4
    for ep in ds.episodes():  # a fresh policy per episode: runs restart at its first step
        cuts = np.flatnonzero(np.diff(ep.actions)) + 1
        assert np.all(cuts % 4 == 0)  # a new action only every 4 steps
    again = make_small("abco/acrobot-pre-held-v0", tmp_path, name="again.hdf5")
    assert _sha(path) == _sha(again)
    variant = make_small("abco/acrobot-pre-held-v0", tmp_path, name="v.hdf5", hold=[1, 3])
    report = abco_data.verify(variant)  # a hold variant's bytes are reproduced and checked
    assert report.num_transitions == 300
    with h5py.File(variant, "r+") as f:
        f.attrs["creation_params"] = f.attrs["creation_params"].replace("[1,3]", "[0,3]")
    with pytest.raises(abco_data.CorruptDatasetError, match="hold"):
        abco_data.verify(variant)


def test_same_id_same_bytes(tmp_path):
    for dataset_id in ("abco/maze3x3-pre-v0", "abco/maze3x3-expert-v0",
                       "abco/cartpole-pre-v0"):
        a = make_small(dataset_id, tmp_path, name="a.hdf5")
        b = make_small(dataset_id, tmp_path, name="b.hdf5")
        assert _sha(a) == _sha(b), dataset_id


def test_no_timestamps_in_objects(tmp_path):
    path = make_small("abco/maze3x3-expert-v0", tmp_path)
    with h5py.File(path) as f:
        names = ["/"]
        f.visit(names.append)
        for name in names:
            assert h5py.h5o.get_info(f[name].id).mtime == 0, name


def test_parameters_are_recorded(tmp_path):
    path = make_small("abco/maze3x3-pre-v0", tmp_path)
    ds = abco_data.open_dataset(path)
    params = json.loads(ds.attrs["creation_params"])
    assert params["layouts"] == 2 and params["seed"] == abco_data.spec(ds.id).params["seed"]
    assert "layouts" in json.loads(ds.attrs["overrides"])
    assert ds.attrs["generator"] == "abco_data"
    assert json.loads(ds.attrs["env_kwargs"]) == {"obs_type": "image", "image_size": 64}


def test_overrides_need_a_path():
    with pytest.raises(ValueError, match="explicit path"):
        abco_data.generate("abco/maze3x3-pre-v0", layouts=1)


def test_default_path_is_the_data_home(tmp_path, monkeypatch):
    monkeypatch.setenv("ABCO_DATA_HOME", str(tmp_path))
    assert abco_data.data_home() == tmp_path
