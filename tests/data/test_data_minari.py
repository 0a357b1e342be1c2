"""Minari export, read back with the real minari package."""

import numpy as np
import pytest
from data_testing import make_small

import abco_data

minari = pytest.importorskip("minari")
from abco_data.minari_export import export_to_minari  # noqa: E402


@pytest.mark.parametrize("dataset_id", ["abco/maze3x3-pre-v0", "abco/maze3x3-expert-v0",
                                        "abco/acrobot-pre-v0"])
def test_minari_reads_an_export(tmp_path, monkeypatch, dataset_id):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    ds = abco_data.open_dataset(make_small(dataset_id, tmp_path))
    export_to_minari(ds)
    m = minari.load_dataset(dataset_id)
    assert m.total_episodes == ds.num_episodes and m.total_steps == ds.num_transitions
    assert m.observation_space == ds.observation_space and m.action_space == ds.action_space
    a = ds.load_arrays()
    actions = a.actions if a.actions is not None else a.idm_eval_actions
    for ep, mine in zip(m.iterate_episodes(), ds.episodes()):
        np.testing.assert_array_equal(ep.observations, mine.observations)  # lossless
        np.testing.assert_array_equal(ep.rewards, mine.rewards)
        np.testing.assert_array_equal(ep.terminations, mine.terminations)
        t = a.episode_transition_starts[mine.index]
        np.testing.assert_array_equal(ep.actions, actions[t : t + mine.length])
    assert dataset_id in minari.list_local_datasets()
    assert len(m.sample_episodes(1)) == 1


def test_existing_export_is_kept(tmp_path):
    path = make_small("abco/mountaincar-pre-v0", tmp_path)
    root = tmp_path / "minari"
    export_to_minari(path, datasets_root=root)
    with pytest.raises(FileExistsError):
        export_to_minari(path, datasets_root=root)
    export_to_minari(path, datasets_root=root, overwrite=True)
    assert sorted(p.name for p in (root / "abco").iterdir()) == [
        "mountaincar-pre-v0", "namespace_metadata.json"]
