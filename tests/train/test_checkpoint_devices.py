"""A checkpoint restores every tensor beside the data it belongs with, whatever device wrote it.

Without a GPU, the ``meta`` device stands in for an accelerator: a method whose data and
sampling indices sit there must get its restored indices there too, while networks and
optimisers stay where the run put them.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from train_testing import tiny_config

from abco_train.harness.checkpoint import load_checkpoint, load_method_state, place_like
from abco_train.harness.loop import train
from abco_train.harness.runtime import seed_everything
from abco_train.harness.training_data import load_training_data
from abco_train.methods.registry import get_method, resolve_config

#: The BCO family's tensors that index (or are) its data: they travel together.
DATA_TENSORS = ("pre_obs", "pre_t", "pre_actions", "pos_obs", "pos_t", "pos_actions", "s_pre",
                "s_pos", "val_t", "val_actions", "expert_obs", "expert_t")


def _tensors(value, path=""):
    if isinstance(value, torch.Tensor):
        yield path, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _tensors(v, f"{path}/{k}")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            yield from _tensors(v, f"{path}/{i}")


def _stopped_run(tiny_data, tmp_path, env: str, method: str):
    cfg = resolve_config(tiny_config(env, method, tiny_data, tmp_path / "run", device="cpu"))
    assert train(cfg, stop_after=1) is None
    return cfg, load_checkpoint(tmp_path / "run" / "checkpoint.pt")


def _fresh_method(cfg):
    rng = seed_everything(cfg.seed, cfg.threads, cfg.deterministic)
    return get_method(cfg.method)(cfg, load_training_data(cfg), rng)


@pytest.mark.parametrize("env", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_a_checkpoint_is_read_into_cpu_memory(tiny_data, tmp_path, env) -> None:
    _, state = _stopped_run(tiny_data, tmp_path, env, "abco")
    devices = {t.device.type for _, t in _tensors(state)}
    assert devices == {"cpu"}


@pytest.mark.parametrize("env", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_restored_indices_land_beside_the_data_they_index(tiny_data, tmp_path, env) -> None:
    cfg, state = _stopped_run(tiny_data, tmp_path, env, "abco")
    method = _fresh_method(cfg)
    # the data and its indices, as if resident on an accelerator (a maze's frames are drawn
    # on demand, no tensor: their indices are enough)
    moved = [n for n in DATA_TENSORS if isinstance(getattr(method, n), torch.Tensor)]
    assert {"pre_t", "s_pre", "s_pos", "pos_t", "pos_actions"} <= set(moved)
    for name in moved:
        setattr(method, name, getattr(method, name).to("meta"))
    load_method_state(method, state, tmp_path / "run" / "checkpoint.pt")
    for name in moved:
        assert getattr(method, name).device.type == "meta", name
    # networks and optimisers stay on the run's device, holding the checkpoint's weights
    saved = state["method"]["policy"]
    for key, value in method.policy.state_dict().items():
        assert value.device.type == "cpu" and torch.equal(value, saved[key]), key
    moments = [s for s in method.idm_opt.state_dict()["state"].values()]
    assert moments and all(t.device.type == "cpu" for s in moments for t in s.values()
                           if isinstance(t, torch.Tensor) and t.dim() > 0)
    # the numpy generator's state is the checkpoint's
    assert method.rng.bit_generator.state == state["method"]["rng"]


def test_place_like_keeps_what_has_no_counterpart() -> None:
    restored = {"a": torch.ones(2), "b": [torch.zeros(1), 3], "c": np.arange(2), "d": torch.ones(1)}
    current = {"a": torch.zeros(2, device="meta"), "b": [torch.zeros(1, device="meta")]}
    placed = place_like(restored, current)
    assert placed["a"].device.type == "meta"
    assert placed["b"][0].device.type == "cpu"  # lists of another length: as they are
    assert placed["d"].device.type == "cpu" and placed["c"] is restored["c"]
