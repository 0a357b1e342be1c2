"""The procedural datasets at small sizes (20 layouts, never the real 10,000): their layouts,
determinism, verification, and the view of their first K layouts."""

import hashlib
import json

import h5py
import numpy as np
import pytest

import abco_data
from abco_data import cli
from abco_data.errors import WrongKindError
from abco_data.generation.generate import layout_split
from abco_data.hub import fetch as hub
from abco_envs.maze.layout import layout_hash, shortest_path_length
from abco_envs.maze.pool import layout_pool
from abco_envs.maze.procedural import procedural_ids

LAYOUTS = 20
SMALL = {"layouts": LAYOUTS, "reference_episodes": 2}
IDS = (
    "abco/maze5x5-procedural-expert-v0",
    "abco/maze5x5-procedural-pre-v0",
    "abco/maze10x10-procedural-expert-v0",
    "abco/maze10x10-procedural-pre-v0",
)


def _small(dataset_id, directory, name="p.hdf5", **extra):
    return abco_data.generate(dataset_id, directory / name, progress=False, **{**SMALL, **extra})


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def pre5(tmp_path_factory):
    return _small("abco/maze5x5-procedural-pre-v0", tmp_path_factory.mktemp("pre5"))


def test_registry_entries():
    assert abco_data.DATASET_IDS[15:19] == IDS
    for dataset_id in IDS:
        s = abco_data.spec(dataset_id)
        assert s.params["layouts"] == 10_000 and s.params["split"] == "procedural"
        assert s.is_maze and s.filename == dataset_id.split("/")[1] + ".hdf5"
    assert abco_data.spec(IDS[0]).params["solutions_per_layout"] == 1
    assert abco_data.spec(IDS[1]).params["episodes_per_layout"] == 2
    assert abco_data.registry.procedural_dataset_id("AbcoMaze5x5-v0", "pre") == IDS[1]
    with pytest.raises(abco_data.UnknownDatasetError, match="no procedural abco dataset"):
        abco_data.registry.procedural_dataset_id("AbcoMaze3x3-v0", "expert")


def test_split_is_part_of_the_id(tmp_path):
    with pytest.raises(TypeError, match="split cannot be overridden"):
        abco_data.generate(IDS[0], tmp_path / "x.hdf5", split="train")
    with pytest.raises(ValueError, match="cannot be made from split 'test'"):
        layout_split({"split": "test"})


@pytest.mark.parametrize("dataset_id", IDS)
def test_layouts_are_the_procedural_split_in_order(tmp_path, dataset_id):
    ds = abco_data.open_dataset(_small(dataset_id, tmp_path))
    n = int(dataset_id.split("maze")[1].split("x")[0])
    a = ds.load_arrays()
    per = 1 if ds.kind == "expert" else 2
    assert a.layout_indices.tolist() == np.repeat(np.arange(LAYOUTS), per).tolist()
    ids = [layout_hash(c) for c in a.layouts]
    assert ids == list(np.repeat(procedural_ids(n, LAYOUTS), per))
    pool = layout_pool(n)
    assert set(ids).isdisjoint(pool.test_ids) and set(ids).isdisjoint(pool.train_ids)
    assert ds.num_layouts == LAYOUTS
    # The evaluation references stay the pool's (train and test), as in the other datasets.
    assert ds.reference.layout_ids == pool.train_ids + pool.test_ids
    assert json.loads(ds.attrs["env_kwargs"]) == {"obs_type": "image", "image_size": 64}
    if ds.kind == "expert":
        for ep in ds.episodes():
            assert ep.terminations[-1] and ep.length == shortest_path_length(ep.layout)


def test_same_id_same_bytes(tmp_path):
    for dataset_id in IDS[:2]:
        a = _small(dataset_id, tmp_path, "a.hdf5")
        b = _small(dataset_id, tmp_path, "b.hdf5")
        assert _sha(a) == _sha(b), dataset_id


@pytest.mark.parametrize("dataset_id", IDS[1:3])
def test_verify_and_check_dataset_pass(tmp_path, dataset_id):
    path = _small(dataset_id, tmp_path, layouts=6)
    report = abco_data.verify(path)
    assert report.frames_rendered == report.num_transitions + report.num_episodes
    assert "with layouts=6" in report.checksum
    ds = abco_data.check_dataset(path, env_id=abco_data.spec(dataset_id).env_id)
    assert abco_data.check_dataset(ds.first_layouts(3)).layouts_taken == 3


def test_first_layouts_is_a_prefix(pre5):
    ds = abco_data.open_dataset(pre5)
    whole = ds.load_arrays()
    for k in (1, 7, LAYOUTS):
        view = ds.first_layouts(k)
        n_ep = int(np.sum(whole.layout_indices < k))
        n_tr = int(whole.episode_lengths[:n_ep].sum())
        assert (view.layouts_taken, view.num_layouts) == (k, k)
        assert (view.num_episodes, view.num_transitions) == (n_ep, n_tr)
        a = view.load_arrays()
        assert np.array_equal(a.observations, whole.observations[: n_tr + n_ep])
        assert np.array_equal(a.actions, whole.actions[:n_tr])
        assert np.array_equal(a.positions, whole.positions[: n_tr + n_ep])
        assert a.layout_indices.max() == k - 1 and len(a.layouts) == n_ep
        assert np.array_equal(view.actions_of_transitions(), whole.actions[:n_tr])
        assert [ep.index for ep in view.episodes()] == list(range(n_ep))
        assert len(view.transition_index()[0]) == n_tr
        picked = view.sample_by_action([5, 5, 5, 5], rng=0)
        assert picked.max() < n_tr
        s, act, s1 = view.read_transitions(picked[:4])
        assert np.array_equal(act, whole.actions[picked[:4]])
    assert ds.num_episodes == len(whole.episode_lengths)  # the whole dataset is untouched
    assert ds.first_layouts(5).first_layouts(2).num_episodes == 4  # a view of a view


def test_first_layouts_equals_generating_fewer_layouts(tmp_path, pre5):
    fewer = abco_data.open_dataset(_small("abco/maze5x5-procedural-pre-v0", tmp_path, layouts=5))
    view = abco_data.open_dataset(pre5).first_layouts(5)
    a, b = view.load_arrays(), fewer.load_arrays()
    for name, value in vars(a).items():
        assert np.array_equal(value, getattr(b, name)), name


def test_first_layouts_torch_view(pre5):
    view = abco_data.open_dataset(pre5).first_layouts(3)
    for in_memory in (False, True):
        torch_view = view.torch_dataset(in_memory=in_memory)
        assert len(torch_view) == view.num_transitions
        with pytest.raises(IndexError):
            torch_view[view.num_transitions]


@pytest.mark.parametrize(
    ("k", "match"),
    [
        (0, "layouts=0 is out of range: .* has 20 layouts; take from 1 to 20"),
        (21, "layouts=21 is out of range"),
        (-3, "layouts=-3 is out of range"),
        (2.5, "must be an integer from 1 to 20, got float"),
        (True, "must be an integer from 1 to 20, got bool"),
        ("3", "must be an integer from 1 to 20, got str"),
    ],
)
def test_bad_layout_counts_are_named(pre5, k, match):
    with pytest.raises(ValueError, match=match):
        abco_data.open_dataset(pre5).first_layouts(k)


def test_first_layouts_needs_a_maze(tmp_path):
    path = abco_data.generate(
        "abco/mountaincar-pre-v0",
        tmp_path / "m.hdf5",
        progress=False,
        transitions=30,
        reference_episodes=1,
        reference_expert_episodes=1,
    )
    with pytest.raises(WrongKindError, match="has no maze layouts"):
        abco_data.open_dataset(path).first_layouts(1)


def test_load_takes_the_first_layouts(pre5, monkeypatch):
    fetched = []
    monkeypatch.setattr(hub, "fetch", lambda dataset_id, **kw: fetched.append(dataset_id) or pre5)
    ds = hub.load(IDS[1], layouts=4, progress=False)
    assert ds.layouts_taken == 4 and ds.num_episodes == 8 and fetched == [IDS[1]]
    # A count beyond the registry's is refused before anything is fetched or generated.
    with pytest.raises(ValueError, match="layouts=10001 is out of range: .* has 10000"):
        hub.load(IDS[1], layouts=10_001, progress=False)
    with pytest.raises(WrongKindError, match="no maze layouts"):
        hub.load("abco/cartpole-pre-v0", layouts=3, progress=False)
    assert fetched == [IDS[1]]


def test_cli_list_and_info(pre5, capsys):
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    for dataset_id in IDS:
        assert dataset_id in out
    assert cli.main(["info", str(pre5), "--layouts", "3"]) == 0
    out = capsys.readouterr().out
    assert "layouts:     3 (the first, of 20)" in out and "episodes:    6" in out
    assert cli.main(["info", str(pre5), "--layouts", "30"]) == cli.EXIT_BAD_INPUT
    assert "layouts=30 is out of range" in capsys.readouterr().err


def test_verify_checks_layouts_against_the_procedural_split(tmp_path):
    path = _small(IDS[0], tmp_path, layouts=4)
    with h5py.File(path, "r+") as f:  # episode 0 now claims procedural layout 1
        f["episodes/layout_index"][0] = 1
    with pytest.raises(
        abco_data.CorruptDatasetError,
        match="episode 0's layout is not layout 1 of the procedural split",
    ):
        abco_data.verify(path, sha256=abco_data.sha256_of(path))
