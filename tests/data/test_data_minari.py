"""Minari export through Minari's public API, read back with ``minari.load_dataset``."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from data_testing import make_small

import abco_data

minari = pytest.importorskip("minari")
from abco_data.interop.minari_export import NO_ACTIONS, export_to_minari  # noqa: E402


def _export(tmp_path, monkeypatch, dataset_id):
    """Export a small ``dataset_id``; return it and Minari's dataset, episodes checked."""
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    ds = abco_data.open_dataset(make_small(dataset_id, tmp_path))
    export_to_minari(ds)
    m = minari.load_dataset(dataset_id)
    assert dataset_id in minari.list_local_datasets()
    _check_episodes(m, ds)
    return ds, m


def _check_episodes(m, ds) -> None:
    assert m.total_episodes == ds.num_episodes and m.total_steps == ds.num_transitions
    assert m.observation_space == ds.observation_space
    for ep, mine in zip(m.iterate_episodes(), ds.episodes(), strict=True):
        np.testing.assert_array_equal(ep.observations, mine.observations)  # lossless
        np.testing.assert_array_equal(ep.rewards, mine.rewards)
        np.testing.assert_array_equal(ep.terminations, mine.terminations)
        np.testing.assert_array_equal(ep.truncations, mine.truncations)
    assert len(m.sample_episodes(1)) == 1


@pytest.mark.parametrize("dataset_id", ["abco/maze3x3-pre-v0", "abco/cartpole-pre-v0"])
def test_pre_demonstrations_export_their_actions(tmp_path, monkeypatch, dataset_id):
    ds, m = _export(tmp_path, monkeypatch, dataset_id)
    assert m.action_space == ds.action_space
    actions = ds.actions_of_transitions()
    for ep, mine in zip(m.iterate_episodes(), ds.episodes()):
        np.testing.assert_array_equal(ep.actions, mine.actions)
        t = ds.load_arrays().episode_transition_starts[mine.index]
        np.testing.assert_array_equal(ep.actions, actions[t : t + mine.length])
    # The recorded env is the one the data came from (mazes: image observations).
    assert m.recover_environment().observation_space == ds.observation_space


@pytest.mark.parametrize("dataset_id", ["abco/maze3x3-expert-v0", "abco/cartpole-expert-v0"])
def test_expert_exports_carry_no_training_actions(tmp_path, monkeypatch, dataset_id):
    ds, m = _export(tmp_path, monkeypatch, dataset_id)
    assert m.action_space == NO_ACTIONS
    idm = ds.actions_of_transitions(idm_eval=True)
    for ep, mine in zip(m.iterate_episodes(), ds.episodes()):
        assert ep.actions.shape == (mine.length, 0)  # no action labels at all
        t = ds.load_arrays().episode_transition_starts[mine.index]
        np.testing.assert_array_equal(ep.infos["idm_eval_actions"], idm[t : t + mine.length])
    assert "IDM accuracy only" in m.storage.metadata["description"]


def test_maze_export_needs_no_prior_import_of_abco_envs(tmp_path):
    path = make_small("abco/maze3x3-pre-v0", tmp_path)
    code = (
        "import sys, minari\n"
        "from abco_data.interop.minari_export import export_to_minari\n"
        f"export_to_minari({str(path)!r}, datasets_root={str(tmp_path / 'm')!r})\n"
        "import os; os.environ['MINARI_DATASETS_PATH'] = " + repr(str(tmp_path / "m")) + "\n"
        "print(minari.load_dataset('abco/maze3x3-pre-v0').total_steps)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0, done.stderr
    assert int(done.stdout.split()[-1]) == abco_data.open_dataset(path).num_transitions


def test_existing_export_is_kept(tmp_path):
    path = make_small("abco/mountaincar-pre-v0", tmp_path)
    root = tmp_path / "minari"
    export_to_minari(path, datasets_root=root)
    with pytest.raises(FileExistsError):
        export_to_minari(path, datasets_root=root)
    export_to_minari(path, datasets_root=root, overwrite=True)
    assert sorted(p.name for p in (root / "abco").iterdir()) == [
        "mountaincar-pre-v0", "namespace_metadata.json"]
    assert sorted(p.name for p in root.iterdir()) == ["abco"]  # no temporary left
