"""Training data keeps maze frames as (layout, agent cell), drawn a minibatch at a time: every
method gets the tensors the decoded frames gave, so runs end with the same numbers."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from train_testing import tiny_config

import abco_data
from abco_data.format.arrays import MazeFrames
from abco_data.torch_view import DeviceFrameTensor, frames_tensor
from abco_train.harness import loop
from abco_train.harness import training_data as training_data_module
from abco_train.harness.loop import train
from abco_train.harness.training_data import TrainingData, load_training_data
from abco_train.methods.bco import family
from abco_train.methods.registry import get_method

ROOT = Path(__file__).resolve().parents[2]
MAZE = "AbcoMaze3x3-v0"


def decoded(data: TrainingData) -> TrainingData:
    """``data`` with its observations decoded into arrays, as training data held them before."""
    return dataclasses.replace(data, pre_obs=np.asarray(data.pre_obs),
                               expert_obs=np.asarray(data.expert_obs))  # fmt: skip


def without_times(record):
    """A final.json or metrics record without what differs between two identical runs."""
    if isinstance(record, dict):
        return {k: without_times(v) for k, v in record.items() if not k.startswith("seconds")}
    if isinstance(record, list):
        return [without_times(v) for v in record]
    return record


def test_maze_frames_are_drawn_and_are_the_files(tiny_data, tmp_path):
    data = load_training_data(tiny_config(MAZE, "bco", tiny_data, tmp_path).resolved())
    expert_file, pre_file = tiny_data(MAZE)
    for obs, path in ((data.pre_obs, pre_file), (data.expert_obs, expert_file)):
        assert isinstance(obs, MazeFrames)
        stored = abco_data.open_dataset(path).load_arrays().observations
        assert np.asarray(obs).tobytes() == stored.tobytes()
    assert data.pre_obs.backgrounds is data.expert_obs.backgrounds  # one table, both datasets
    classic = load_training_data(tiny_config("CartPole-v1", "bco", tiny_data, tmp_path)
                                 .resolved())  # fmt: skip
    assert isinstance(classic.pre_obs, np.ndarray) and isinstance(classic.expert_obs, np.ndarray)


def test_frames_that_do_not_redraw_stay_the_files(tiny_data, tmp_path):
    """A file whose frames are not its layouts' and positions' renderings (refused by
    ``check_dataset``, so opened directly here) is trained on its own frames, decoded."""
    path = tmp_path / "pre.hdf5"
    path.write_bytes(Path(tiny_data(MAZE)[1]).read_bytes())
    with h5py.File(path, "r+") as f:
        f["observations"][3, 20, 4] ^= 1  # another colour index in two pixels
    ds = abco_data.open_dataset(path)
    (obs,) = training_data_module._observations([ds], [ds.load_arrays(observations=False)])
    assert isinstance(obs, np.ndarray)
    assert obs.tobytes() == ds.load_arrays().observations.tobytes()


@pytest.mark.parametrize("method", ["bc", "bco", "bco-alpha", "bco-alpha-torabi", "abco", "iupe"])
def test_runs_end_as_with_decoded_frames(method, tiny_data, tmp_path, monkeypatch):
    cfg = tiny_config(MAZE, method, tiny_data, tmp_path / "drawn", augment="transpose")
    drawn = train(cfg)
    monkeypatch.setattr(loop, "load_training_data", lambda c: decoded(load_training_data(c)))
    old = train(dataclasses.replace(cfg, run_dir=str(tmp_path / "decoded")))
    assert drawn is not None and old is not None
    assert without_times(drawn) == without_times(old)
    metrics = [[without_times(json.loads(line)) for line in (tmp_path / run / "metrics.jsonl")
                .read_text().splitlines()] for run in ("drawn", "decoded")]  # fmt: skip
    assert metrics[0] == metrics[1]
    assert ("idm_loss" in json.dumps(metrics)) == (method != "bc")  # the IDM's losses compared
    # frames drawn by the device view, as on a GPU (the view here on the CPU): the same run
    monkeypatch.setattr(loop, "load_training_data", load_training_data)
    monkeypatch.setattr(family, "frames_tensor", lambda obs, device: DeviceFrameTensor(
        obs, torch.device("cpu")) if isinstance(obs, MazeFrames) else frames_tensor(obs))
    on_device = train(dataclasses.replace(cfg, run_dir=str(tmp_path / "device")))
    assert without_times(on_device) == without_times(drawn)


def test_minibatches_are_the_decoded_ones(tiny_data, tmp_path):
    cfg = tiny_config(MAZE, "abco", tiny_data, tmp_path, device="cpu").resolved()
    data = load_training_data(cfg)
    new = get_method("abco")(cfg, data, np.random.default_rng(0))
    old = get_method("abco")(cfg, decoded(data), np.random.default_rng(0))
    idx = torch.tensor([3, 0, 7, 3])
    for a, b in zip(new._expert_pairs(idx), old._expert_pairs(idx)):
        assert a.dtype == b.dtype == torch.uint8 and torch.equal(a, b)
    rows = new.pre_t[idx]
    assert torch.equal(new.pre_obs[rows + 1], old.pre_obs[rows + 1])
    assert new.pos_obs.dtype == old.pos_obs.dtype and new.pos_obs.shape == old.pos_obs.shape
    # ILPO's targets, computed from every expert pair at once
    cfg = tiny_config(MAZE, "ilpo", tiny_data, tmp_path, device="cpu").resolved()
    ilpo = [get_method("ilpo")(cfg, d, np.random.default_rng(0)) for d in (data, decoded(data))]
    assert torch.equal(ilpo[0].expert_targets, ilpo[1].expert_targets)
    view = frames_tensor(data.expert_obs)
    assert torch.equal(view[ilpo[0].expert_t], torch.from_numpy(np.asarray(data.expert_obs))
                       [ilpo[1].expert_t])  # fmt: skip


def test_memory_benchmark_runs_tiny(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]), "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "memory_training.py"),
                           "--tiny"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    for needle in ("peak GiB", "CPU s", "train s/iter", "AbcoMaze5x5-v0 this checkout",
                   "not judged"):  # fmt: skip
        assert needle in done.stdout, done.stdout
