"""Checkpoints that are data, not code: numpy state stored bit for bit, every checkpoint
read with ``weights_only=True`` and checked before use, a pickle payload never run (refused
in one line by ``load_policy``, ``abco play``, a resume and a run of another config), an older
abco's checkpoint converted only on request, and then resumed as if never stopped."""

from __future__ import annotations

import enum
import io
import json
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from train_testing import one_error_line, tiny_config, train_argv

import abco_train.harness.checkpoint as checkpoint
from abco_train.cli import main
from abco_train.harness.checkpoint import (
    LegacyCheckpointError,
    convert_legacy_checkpoint,
    from_saved,
    to_saved,
)
from abco_train.harness.loop import train
from abco_train.harness.run_folder import RunFolderError
from abco_train.harness.trained_policy import load_policy

DROP = ("figures", "seconds")


def _same_result(a: dict[str, Any], b: dict[str, Any]) -> None:
    assert {k: v for k, v in a.items() if k not in DROP} == \
        {k: v for k, v in b.items() if k not in DROP}  # fmt: skip


@pytest.fixture(scope="module")
def stopped(tiny_data, tmp_path_factory) -> tuple[Any, Path, dict[str, Any]]:
    """A CartPole ABCO run stopped after its first of two iterations, and the final result of
    the same run uninterrupted: ``(config, run folder, final)``."""
    root = tmp_path_factory.mktemp("stopped")
    full = train(tiny_config("CartPole-v1", "abco", tiny_data, root / "full"))
    cfg = tiny_config("CartPole-v1", "abco", tiny_data, root / "cut")
    assert train(cfg, stop_after=1) is None and full is not None
    return cfg, root / "cut", full


def _copy(stopped: tuple[Any, Path, dict[str, Any]], tmp_path: Path) -> tuple[Any, Path]:
    cfg, folder, _ = stopped
    run_dir = tmp_path / "run"
    shutil.copytree(folder, run_dir)
    return cfg.replace(run_dir=str(run_dir)), run_dir


def _state(run_dir: Path) -> dict[str, Any]:
    return torch.load(run_dir / "checkpoint.pt", weights_only=True)


def _save(run_dir: Path, state: Any) -> None:
    torch.save(state, run_dir / "checkpoint.pt")


# -- numpy state, bit for bit ------------------------------------------------------------------


def test_numpy_state_comes_back_bit_for_bit_through_a_weights_only_load() -> None:
    state = {
        "ints": np.arange(-3, 3, dtype=np.int16), "wins": np.array([True, False]),
        "obs": np.random.default_rng(0).random((2, 3)).astype(np.float32)[:, ::2],  # a view
        "big_endian": np.arange(4, dtype=">i4"), "names": np.array(["a", "bc"]),
        "times": np.array(["2026-01-01"], dtype="datetime64[D]"), "empty": np.zeros((0, 5)),
        "scalar": np.float32(0.1), "flag": np.bool_(True), "nested": [(np.uint8(7), None)],
        "rng": np.random.default_rng(5).bit_generator.state, "tensor": torch.arange(3),
        "module": torch.nn.BatchNorm1d(2).state_dict(),
    }  # fmt: skip
    buffer = io.BytesIO()
    torch.save(to_saved(state), buffer)
    buffer.seek(0)
    back = from_saved(torch.load(buffer, weights_only=True))
    for key in ("ints", "wins", "obs", "big_endian", "names", "times", "empty"):
        assert type(back[key]) is np.ndarray and back[key].dtype == state[key].dtype, key
        assert back[key].shape == state[key].shape and back[key].tobytes() == state[key].tobytes()
        assert back[key].flags.writeable, key  # a method may change it in place (np.add.at)
    assert type(back["scalar"]) is np.float32 and back["scalar"] == state["scalar"]
    assert type(back["flag"]) is np.bool_ and type(back["nested"][0][0]) is np.uint8
    assert isinstance(back["nested"][0], tuple) and back["rng"] == state["rng"]
    assert torch.equal(back["tensor"], state["tensor"])
    assert back["module"]._metadata == state["module"]._metadata  # versions kept


class _Thing:
    pass


class _Kind(enum.IntEnum):
    A = 1


@pytest.mark.parametrize(("state", "where"), [
    ({"x": _Thing()}, "state['x'] is a "),
    ({"x": [1, np.array([object()], dtype=object)]},
     "state['x'][1] is a numpy array of dtype object"),
    ({"x": _Kind.A}, "state['x'] is a "),
    ({"x": {1, 2}}, "state['x'] is a builtins.set"),
    ({checkpoint.NUMPY_TAG: 1}, "reserve"),
])  # fmt: skip
def test_what_is_no_data_is_refused_when_saved(state, where) -> None:
    with pytest.raises(TypeError, match=where.replace("[", r"\[").replace("]", r"\]")):
        to_saved(state)


def _tag(**changes: Any) -> dict[str, Any]:
    return {**to_saved(np.arange(4, dtype=np.int32)), **changes}


@pytest.mark.parametrize("tag", [
    _tag(shape=[5]), _tag(shape=[-4]), _tag(shape="4"), _tag(scalar=1),
    _tag(**{checkpoint.NUMPY_TAG: "O"}), _tag(**{checkpoint.NUMPY_TAG: "not a dtype"}),
    _tag(**{checkpoint.NUMPY_TAG: "V16"}), _tag(bytes=torch.zeros(16)), _tag(extra=1),
    _tag(bytes=torch.zeros(1, dtype=torch.uint8).expand(16)),  # 16 bytes over 1
])  # fmt: skip
def test_a_tag_that_is_no_array_is_refused(tag) -> None:
    with pytest.raises(RunFolderError, match=r"checkpoint\['x'\] is"):
        from_saved({"x": tag})


def test_a_tensor_larger_than_its_data_is_refused() -> None:
    buffer = io.BytesIO()
    torch.save({"pos_obs": torch.zeros(1).expand(10**12)}, buffer)  # 4 bytes, posing as 4 TB
    buffer.seek(0)
    with pytest.raises(RunFolderError, match="over 4 bytes of data"):
        from_saved(torch.load(buffer, weights_only=True))


def test_deep_or_exploding_containers_are_refused(monkeypatch) -> None:
    deep: Any = []
    for _ in range(200):
        deep = [deep]
    with pytest.raises(RunFolderError, match="nests deeper"):
        from_saved(deep)
    shared: Any = [0]
    for _ in range(60):  # 60 bytes of pickle, 2**60 values when walked
        shared = [shared, shared]
    monkeypatch.setattr(checkpoint, "MAX_VALUES", 10_000)
    with pytest.raises(RunFolderError, match="more than 10,000 values"):
        from_saved(shared)


def test_checkpoints_are_read_with_weights_only(stopped, tmp_path) -> None:
    _, run_dir = _copy(stopped, tmp_path)
    state = _state(run_dir)  # loads with weights_only=True: data only
    assert state["format"] == checkpoint.FORMAT
    labels = state["method"]["labels"]
    assert labels[checkpoint.NUMPY_TAG] == np.dtype(np.int64).str


# -- a pickle payload never runs ---------------------------------------------------------------


class _System:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> Any:
        return os.system, (f"touch {self.marker}",)


class _Exec:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> Any:
        return exec, (f"open({str(self.marker)!r}, 'w').close()",)


@pytest.fixture(params=[_System, _Exec])
def booby_trapped(request, stopped, tmp_path) -> tuple[Any, Path, Path]:
    """A run folder whose ``checkpoint.pt`` would create ``marker`` if it were unpickled."""
    cfg, run_dir = _copy(stopped, tmp_path)
    marker = tmp_path / "marker"
    state = _state(run_dir)
    state["method"]["labels"] = request.param(marker)
    _save(run_dir, state)
    return cfg, run_dir, marker


def test_a_pickle_payload_never_runs(booby_trapped, capsys) -> None:
    cfg, run_dir, marker = booby_trapped
    before = (run_dir / "checkpoint.pt").read_bytes()
    with pytest.raises(LegacyCheckpointError, match="abco convert-checkpoint"):
        load_policy(run_dir)
    with pytest.raises(LegacyCheckpointError, match="could run code"):
        train(cfg)  # resuming
    with pytest.raises(LegacyCheckpointError):
        train(cfg.replace(seed=1))  # another config: refused before the configs are compared
    assert main(["play", str(run_dir), "--episodes", "0", "--quiet"]) == 2
    one_error_line(capsys.readouterr().err, "checkpoint.pt holds pickled Python objects",
              f"abco convert-checkpoint {run_dir}", "if you trust")
    assert main(train_argv(cfg)) == 2
    one_error_line(capsys.readouterr().err, "abco convert-checkpoint")
    assert not marker.exists()
    assert (run_dir / "checkpoint.pt").read_bytes() == before  # nothing replaced


# -- checked before use ------------------------------------------------------------------------


def _set_iteration(value: Any) -> Any:
    return lambda s: s.update(iteration=value)


def _labels_away(s: dict[str, Any]) -> None:
    del s["method"]["labels"]


def _wider_policy(s: dict[str, Any]) -> None:
    key = next(k for k in s["method"]["policy"] if k.endswith("weight"))
    s["method"]["policy"][key] = torch.zeros(999, 3)


@pytest.mark.parametrize(("change", "message"), [
    (_set_iteration(-100), "is no abco checkpoint (iteration -100)"),
    (_set_iteration(2), "is at iteration 2 of a run of 2 iterations"),
    (_set_iteration("0"), "is no abco checkpoint (iteration 0)"),
    (_set_iteration(True), "is no abco checkpoint (iteration True)"),
    (lambda s: s.pop("iteration"), "is no abco checkpoint (no iteration)"),
    (lambda s: s.update(torch_rng=torch.zeros(3)), "no generator state of torch"),
    (lambda s: s.update(interactions={"rl": -1}), "interaction counts"),
    (lambda s: s.update(format=99), "format 99, not 2"),
    (lambda s: s.update(method=[1]), "method state or config that is not a dict"),
    (_labels_away, "does not fit the run's BCOFamily (KeyError: 'labels')"),
    (lambda s: s["method"].update(pos_runs="x"), "does not fit the run's BCOFamily (TypeError"),
    (_wider_policy, "does not fit the run's BCOFamily (RuntimeError: Error(s) in loading"),
])  # fmt: skip
def test_a_checkpoint_is_checked_before_use(stopped, tmp_path, capsys, change, message) -> None:
    cfg, run_dir = _copy(stopped, tmp_path)
    state = _state(run_dir)
    change(state)
    _save(run_dir, state)
    metrics = (run_dir / "metrics.jsonl").read_bytes()
    with pytest.raises(RunFolderError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_policy(run_dir)
    with pytest.raises(RunFolderError):
        train(cfg)  # never 100 iterations from -100, nor any from a state that does not fit
    assert (run_dir / "metrics.jsonl").read_bytes() == metrics
    assert not (run_dir / "final.json").exists()
    assert main(["play", str(run_dir), "--episodes", "0", "--quiet"]) == 2
    one_error_line(capsys.readouterr().err, message)


def test_a_checkpoint_that_is_no_file_is_refused(stopped, tmp_path) -> None:
    _, run_dir = _copy(stopped, tmp_path)
    ckpt = run_dir / "checkpoint.pt"
    ckpt.unlink()
    os.mkfifo(ckpt)  # a read would wait for a writer forever
    with pytest.raises(RunFolderError, match="is a FIFO .*not a regular file"):
        load_policy(run_dir)
    ckpt.unlink()
    ckpt.symlink_to("/dev/zero")  # endless
    with pytest.raises(RunFolderError, match="is a character device, not a regular file"):
        load_policy(run_dir)


# -- an older abco's checkpoint ----------------------------------------------------------------


def test_an_older_checkpoint_is_refused_then_converted_and_resumes_exactly(
        stopped, tmp_path, capsys) -> None:  # fmt: skip
    cfg, run_dir = _copy(stopped, tmp_path)
    state = from_saved(_state(run_dir))  # numpy arrays again, pickled as an older abco did
    del state["format"]
    assert isinstance(state["method"]["pos_runs"], np.ndarray)
    _save(run_dir, state)
    with pytest.raises(LegacyCheckpointError):
        load_policy(run_dir)
    assert main(train_argv(cfg)) == 2
    one_error_line(capsys.readouterr().err, f"abco convert-checkpoint {run_dir}")
    assert convert_legacy_checkpoint(run_dir) == run_dir / "checkpoint.pt"
    converted = _state(run_dir)  # data now
    assert converted["format"] == checkpoint.FORMAT
    assert convert_legacy_checkpoint(run_dir) == run_dir / "checkpoint.pt"  # nothing to do
    assert _state(run_dir).keys() == converted.keys()
    resumed = train(cfg)
    assert resumed is not None
    _same_result(resumed, stopped[2])  # as if never stopped
    rows = [json.loads(x) for x in (run_dir / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [0, 1]


def test_converting_what_is_not_there_or_damaged_is_one_line(stopped, tmp_path) -> None:
    _, run_dir = _copy(stopped, tmp_path)
    with pytest.raises(RunFolderError, match="holds no checkpoint.pt to convert"):
        convert_legacy_checkpoint(tmp_path / "elsewhere")
    ckpt = run_dir / "checkpoint.pt"
    ckpt.write_bytes(ckpt.read_bytes()[:100])
    with pytest.raises(RunFolderError, match="is damaged"):
        convert_legacy_checkpoint(run_dir)
    buffer = io.BytesIO()
    torch.save({"iteration": 0, "thing": _Thing()}, buffer)  # a pickle of no data at all
    ckpt.write_bytes(buffer.getvalue())
    with pytest.raises(RunFolderError, match="cannot be converted: checkpoint\\['thing'\\]"):
        convert_legacy_checkpoint(run_dir)
    assert ckpt.read_bytes() == buffer.getvalue()


@pytest.mark.parametrize("crafted", [
    '{"iteration": "0"}', '{"iteration": 0, "eval": 5}', "[" * 100_000, "NaN",
    '{"iteration": 0, "seconds": 1, "train": {}, "eval": {"performance": 1, "aer": 1,'
    ' "success_rate": 1}, "label_distribution": [1, 2, 3]}',  # CartPole has 2 actions
    '{"iteration": 0, "seconds": 1, "train": {"idm_chance": "x"}, "eval": {}}',
])  # fmt: skip
def test_crafted_metrics_lines_refuse_the_resumption(stopped, tmp_path, crafted) -> None:
    cfg, run_dir = _copy(stopped, tmp_path)
    metrics = run_dir / "metrics.jsonl"
    metrics.write_text("\n".join([crafted, *metrics.read_text().splitlines()]) + "\n")
    before = metrics.read_bytes()
    with pytest.raises(RunFolderError, match="metrics.jsonl line 1 is no metrics record"):
        train(cfg)
    assert metrics.read_bytes() == before


def test_a_last_metrics_line_cut_by_a_kill_is_dropped(stopped, tmp_path) -> None:
    cfg, run_dir = _copy(stopped, tmp_path)
    metrics = run_dir / "metrics.jsonl"
    metrics.write_text(metrics.read_text() + '{"iteration": 1, "tra')
    resumed = train(cfg)
    assert resumed is not None
    _same_result(resumed, stopped[2])
    rows = [json.loads(x) for x in metrics.read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [0, 1]


@pytest.mark.parametrize("config", ["[]", '{"env": "CartPole-v1", "seed": "x"}', "[" * 100_000,
                                    '{"env": "Cart'])  # fmt: skip
def test_a_damaged_config_json_refuses_the_resumption(stopped, tmp_path, config) -> None:
    cfg, run_dir = _copy(stopped, tmp_path)
    (run_dir / "config.json").write_text(config)
    with pytest.raises(RunFolderError, match="config"):
        train(cfg)
    assert (run_dir / "config.json").read_text() == config


def test_metrics_without_the_checkpointed_iterations_refuse_the_resumption(stopped,
                                                                           tmp_path) -> None:
    cfg, run_dir = _copy(stopped, tmp_path)
    (run_dir / "metrics.jsonl").write_text("not json\n")  # a last line, but nothing before it
    with pytest.raises(RunFolderError, match="lacks the record of iteration 0"):
        train(cfg)
