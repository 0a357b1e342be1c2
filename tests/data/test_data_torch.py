"""The torch view: items, DataLoader workers (one handle each), in-memory mode."""

import subprocess
import sys

import numpy as np
import pytest
from data_testing import make_small

import abco_data

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def pre(tmp_path_factory):
    return abco_data.open_dataset(make_small("abco/maze3x3-pre-v0", tmp_path_factory.mktemp("t")))


def test_items_are_transitions(pre):
    view = pre.torch_dataset()
    a = pre.load_arrays()
    obs_t, obs_t1 = pre.transition_index()
    assert len(view) == pre.num_transitions
    for k in (0, 5, len(view) - 1, -1):
        s, act, s1 = view[k]
        k %= len(view)
        np.testing.assert_array_equal(s.numpy(), a.observations[obs_t[k]])
        np.testing.assert_array_equal(s1.numpy(), a.observations[obs_t1[k]])
        assert int(act) == a.actions[k]
    with pytest.raises(IndexError):
        view[len(view)]


def test_expert_items_have_no_actions(tmp_path):
    ds = abco_data.open_dataset(make_small("abco/maze3x3-expert-v0", tmp_path))
    assert len(ds.torch_dataset()[0]) == 2
    assert len(ds.torch_dataset(idm_eval_actions=True)[0]) == 3


def test_dataloader_workers_match_in_memory(pre):
    lazy = pre.torch_dataset()
    memory = pre.torch_dataset(in_memory=True)
    loader = torch.utils.data.DataLoader(lazy, batch_size=16, num_workers=2)
    batches = list(loader)
    assert not lazy._h5.is_open  # the parent never opened a handle: each worker did
    s = torch.cat([b[0] for b in batches])
    a = torch.cat([b[1] for b in batches])
    ref = torch.utils.data.default_collate([memory[i] for i in range(len(memory))])
    assert torch.equal(s, ref[0]) and torch.equal(a, ref[1])


def test_subset_by_sampled_indices(pre):
    idx = pre.sample_by_action([2, 2, 2, 2], 0)
    view = pre.torch_dataset(in_memory=True, indices=idx)
    acts = pre.actions_of_transitions()
    assert len(view) == 8
    assert sorted(int(view[i][1]) for i in range(8)) == sorted(acts[idx].tolist())


def test_import_abco_data_does_not_import_torch():
    code = "import sys, abco_data; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
