"""User datasets: ids of their own, the user manifest, and every reader treating them as it
treats the built-in ones (checksums included)."""

from __future__ import annotations

import json
import multiprocessing

import pytest

import abco_data
from abco_data import cli
from abco_data.errors import (
    ChecksumError,
    CorruptDatasetError,
    DatasetError,
    InvalidParameterError,
    UnknownDatasetError,
    WrongKindError,
)
from abco_data.hub.manifest import cached_path
from abco_data.user.datasets import (
    read_user_manifest,
    register_user_dataset,
    user_manifest_path,
)
from abco_data.user.ids import check_user_id, is_user_id, user_id_for_file

SMALL = {"reference_episodes": 2, "reference_expert_episodes": 1, "progress": False}


def push_right(obs):
    return 1


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch):
    """A data home (and user manifest) of each test's own."""
    monkeypatch.setenv("ABCO_DATA_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def _record(dataset_id=None, out=None, **kwargs):
    return abco_data.record("CartPole-v1", push_right, kind="expert", episodes=2, id=dataset_id,
                            out=out, **{**SMALL, **kwargs})


def test_user_ids_keep_out_of_the_built_in_namespace():
    assert is_user_id("local/cartpole-mine-v0") and is_user_id("me/x.y_z-v12")
    for bad, message in (("abco/cartpole-mine-v0", "namespace 'abco' is abco's own"),
                         ("ABCO/cartpole-mine-v0", "namespace 'ABCO' is abco's own"),
                         ("local/cartpole", "NAMESPACE/NAME-vN"),
                         ("local/../x-v0", "NAMESPACE/NAME-vN"),
                         ("a/b/c-v0", "NAMESPACE/NAME-vN"), (3, "NAMESPACE/NAME-vN")):
        assert not is_user_id(bad)
        with pytest.raises(InvalidParameterError, match=message):
            check_user_id(bad)
    assert user_id_for_file("/x/My Run!.hdf5") == "local/My-Run-v0"
    assert user_id_for_file("runs/pole-v3.hdf5") == "local/pole-v3"


def test_a_built_in_id_is_refused_in_one_line(tmp_path, capsys):
    with pytest.raises(InvalidParameterError, match="namespace 'abco' is abco's own"):
        _record("abco/cartpole-expert-v0")
    with pytest.raises(InvalidParameterError, match="abco's own"):
        register_user_dataset("abco/cartpole-expert-v0", tmp_path / "x", env_id="CartPole-v1",
                              kind="expert")
    assert cli.main(["record", "--env", "CartPole-v1", "--kind", "pre", "--episodes", "1",
                     "--id", "abco/cartpole-pre-v0", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "abco's own" in err
    assert read_user_manifest() == {}


def test_a_user_id_never_shadows_a_built_in_one(home, capsys):
    path = _record("local/cartpole-expert-v0")
    assert path == home / "local" / "cartpole-expert-v0.hdf5"
    assert cached_path("abco/cartpole-expert-v0") == home / "cartpole-expert-v0.hdf5"
    ds = abco_data.load("local/cartpole-expert-v0")
    assert ds.id == "local/cartpole-expert-v0" and ds.path == path
    with pytest.raises(WrongKindError, match="abco/cartpole-expert-v0 holds CartPole-v1"):
        abco_data.load("abco/cartpole-expert-v0", layouts=1)  # the built-in's spec answers
    assert cli.main(["list"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()
            if "/cartpole-expert-v0" in line]
    assert [(r[0], r[-2] == "user", r[-1]) for r in rows] == [
        ("abco/cartpole-expert-v0", False, "no"), ("local/cartpole-expert-v0", True, "yes")]


def test_registered_datasets_load_verify_and_show(home, capsys):
    path = _record("local/right-v0")
    entry = read_user_manifest()["local/right-v0"]
    assert entry.path == path and entry.size == path.stat().st_size
    assert entry.sha256 == abco_data.sha256_of(path) and entry.kind == "expert"
    stored = json.loads(user_manifest_path().read_text())["datasets"]["local/right-v0"]
    assert stored["path"] == "local/right-v0.hdf5"  # relative to the home, which may move
    assert abco_data.load("local/right-v0").num_episodes == 2
    checked = abco_data.verify("local/right-v0").checksum
    assert checked == "the user manifest entry of local/right-v0"
    assert abco_data.check_dataset(path, kind="expert", env_id="CartPole-v1").path == path
    assert cli.main(["list"]) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if "local/right-v0" in line)
    assert row.split()[1:3] == ["CartPole-v1", "expert"] and "user" in row
    assert cli.main(["info", "local/right-v0"]) == 0
    out = capsys.readouterr().out
    assert f"sha256 {entry.sha256}" in out and "episodes:    2" in out and str(path) in out
    assert cli.main(["verify", "local/right-v0"]) == 0
    assert "match the user manifest entry of local/right-v0" in capsys.readouterr().out


def test_a_damaged_byte_fails_loading_and_verify_naming_the_file(capsys):
    path = _record("local/damaged-v0")
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    for call in (lambda: abco_data.load("local/damaged-v0"),
                 lambda: abco_data.verify("local/damaged-v0"),
                 lambda: abco_data.verify(path),
                 lambda: abco_data.check_dataset(path)):
        with pytest.raises(ChecksumError) as info:
            call()
        assert str(path) in str(info.value) and "\n" not in str(info.value)
    for args in (["verify", "local/damaged-v0"], ["verify", str(path)]):
        assert cli.main(args) == 1
        err = capsys.readouterr().err
        assert err.startswith("error: ") and str(path) in err and err.count("\n") == 1


def test_a_file_written_without_an_id_loads_as_a_path(tmp_path):
    path = _record(out=tmp_path / "elsewhere" / "my pole.hdf5")
    ds = abco_data.open_dataset(path)
    assert ds.id == "local/my-pole-v0"  # its own id, a user one: no "unknown dataset id"
    assert abco_data.check_dataset(path, kind="expert").num_transitions == ds.num_transitions
    assert read_user_manifest() == {}
    with pytest.raises(UnknownDatasetError, match="no user dataset of that id is registered"):
        abco_data.load("local/my-pole-v0")
    # A file's own id may not be one that is registered: its bytes would fail that entry.
    _record("local/taken-v0")
    with pytest.raises(InvalidParameterError, match="is a registered user dataset"):
        _record(out=tmp_path / "taken.hdf5")


def test_registering_again_needs_overwrite(tmp_path):
    first = _record("local/again-v0")
    with pytest.raises(InvalidParameterError, match="already registered"):
        _record("local/again-v0", seed=9)
    second = _record("local/again-v0", out=tmp_path / "again.hdf5", seed=9, overwrite=True)
    assert read_user_manifest()["local/again-v0"].path == second != first
    assert abco_data.load("local/again-v0").path == second


def test_unknown_ids_and_a_bad_manifest_end_in_one_line(home, capsys):
    assert cli.main(["info", "local/nothing-v0"]) == 2
    assert "no user dataset of that id is registered" in capsys.readouterr().err
    home.mkdir(parents=True)
    user_manifest_path().write_text("{not json")
    with pytest.raises(DatasetError, match="cannot read the user dataset manifest"):
        abco_data.load("local/nothing-v0")
    assert cli.main(["list"]) == 1
    err = capsys.readouterr().err
    assert str(user_manifest_path()) in err and err.count("\n") == 1


def test_ids_no_writer_gives_are_still_refused(tmp_path):
    import h5py
    from data_testing import make_small

    path = _record(out=tmp_path / "x.hdf5")
    with h5py.File(path, "a") as f:
        f.attrs["dataset_id"] = "abco/madeup-expert-v0"
    with pytest.raises(CorruptDatasetError, match="unknown dataset id 'abco/madeup-expert-v0'"):
        abco_data.open_dataset(path)
    # abco's own generator writes built-in ids only: a built-in file renamed is no user file.
    built_in = make_small("abco/cartpole-pre-v0", tmp_path)
    with h5py.File(built_in, "a") as f:
        f.attrs["dataset_id"] = "local/renamed-v0"
    with pytest.raises(CorruptDatasetError, match="unknown dataset id 'local/renamed-v0'"):
        abco_data.open_dataset(built_in)


def _register_many(args):
    home, prefix, file = args
    for i in range(5):
        register_user_dataset(f"local/{prefix}{i}-v0", file, env_id="CartPole-v1",
                              kind="expert", home=home)


def test_processes_registering_at_once_all_land(home, tmp_path):
    path = _record(out=tmp_path / "shared.hdf5")
    with multiprocessing.get_context("fork").Pool(3) as pool:
        pool.map(_register_many, [(home, p, path) for p in "abc"])
    assert sorted(read_user_manifest(home)) == sorted(f"local/{p}{i}-v0" for p in "abc"
                                                      for i in range(5))


def test_the_trainer_takes_a_user_file_as_its_expert_data(tmp_path):
    from abco_train.harness.training_data import resolve_dataset

    path = _record("local/for-training-v0")
    assert resolve_dataset(str(path), "CartPole-v1", "expert").id == "local/for-training-v0"
