"""The ``abco`` command line at its edge: bad options and damaged run folders end in one line
and exit code 2 before any work; a finished run answers at once; a trained policy loads,
reproduces its evaluation and plays."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from train_testing import tiny_config

import abco_train
from abco_train.cli import build_parser, main
from abco_train.config.run import ConfigError, RunConfig
from abco_train.harness.loop import train
from abco_train.methods.registry import resolve_config


def _train_args(tiny_data, env: str, run_dir: Path, *extra: str) -> list[str]:
    expert, pre = tiny_data(env)
    return ["train", "--env", env, "--method", "bco", "--idm-epochs", "1", "--policy-epochs", "1",
            "--iterations", "0", "--eval-episodes", "2", "--eval-layouts", "2",
            "--eval-max-steps", "30", "--expert-data", expert, "--pre-data", pre,
            "--run-dir", str(run_dir), "--quiet", "--no-plots", *extra]  # fmt: skip


@pytest.mark.parametrize(("option", "message"), [
    (["--seed", "-1"], "--seed must be >= 0"),
    (["--threads", "0"], "--threads must be >= 1"),
    (["--eval-episodes", "0"], "--eval-episodes must be >= 1"),
    (["--lr", "-0.1"], "--lr must be > 0"),
    (["--lr", "0"], "--lr must be > 0"),
    (["--iterations", "-1"], "--iterations must be >= 0"),
    (["--batch-size", "-3"], "--batch-size must be >= 1"),
    (["--idm-epochs", "-1"], "--idm-epochs must be >= 1"),
    (["--expert-episodes", "0"], "--expert-episodes must be >= 1"),
    (["--arch", "cnn"], "--arch cnn does not fit CartPole-v1"),
    (["--method", "nope"], "unknown method 'nope'"),
    (["--env", "Nope-v0"], "unknown env id 'Nope-v0'"),
    (["--plugin", "missing_plugin.py"], "plugin file missing_plugin.py does not exist"),
    (["--plugin", "no_such_module_xyz"], "plugin module 'no_such_module_xyz' not found"),
])  # fmt: skip
def test_bad_option_is_one_line_and_exit_2(tmp_path, capsys, option, message) -> None:
    run_dir = tmp_path / "run"
    code = main(["train", "--env", "CartPole-v1", "--quiet", "--run-dir", str(run_dir), *option])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not run_dir.exists()  # nothing started


@pytest.mark.parametrize("option", [["--preset", "bogus"], ["--preset", "gpu"],
                                    ["--protocol", "papr"], ["--arch", "resnet"],
                                    ["--method-options", "[1]"], ["--seed", "x"]])
def test_bad_choice_or_type_is_refused_by_the_parser(capsys, option) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--env", "CartPole-v1", *option])
    assert exit_info.value.code == 2
    assert option[0] in capsys.readouterr().err


def test_a_plugin_that_fails_to_import_is_named(tmp_path, capsys) -> None:
    plugin = tmp_path / "broken.py"
    plugin.write_text("raise RuntimeError('half-written plugin')\n")
    assert main(["train", "--env", "CartPole-v1", "--plugin", str(plugin), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "broken.py failed to import" in err and "half-written plugin" in err


def test_validate_names_the_option() -> None:
    with pytest.raises(ConfigError, match="--idm-epochs must be >= 1, got 0"):
        resolve_config(RunConfig(method_options={"idm_epochs": 0}))


def test_help_shows_defaults_and_imports_no_torch() -> None:
    code = ("import sys; from abco_train.cli import build_parser; "
            "h = build_parser()._subparsers._group_actions[0].choices['train'].format_help(); "
            "assert 'torch' not in sys.modules, 'torch imported'; print(h)")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout  # fmt: skip
    words = " ".join(out.split())  # argparse wraps to the terminal's width
    assert "(default: abco)" in words and "(default: 1)" in words  # --method, --threads


def test_version(capsys) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--version"])
    assert capsys.readouterr().out.strip() == f"abco {abco_train.__version__}"


def test_report_of_an_empty_folder_is_refused(tmp_path, capsys) -> None:
    assert main(["report", str(tmp_path)]) == 2
    assert "holds no run folders" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "absent")]) == 2


def test_damaged_run_folder(tiny_data, tmp_path, capsys) -> None:
    cfg = tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "run")
    assert train(cfg, stop_after=1) is None
    ckpt = tmp_path / "run" / "checkpoint.pt"
    metrics = tmp_path / "run" / "metrics.jsonl"
    metrics.write_text(metrics.read_text() + '{"iteration": 1, "tr')  # a kill mid-line
    data = ckpt.read_bytes()
    ckpt.write_bytes(data[: len(data) // 2])
    args = ["train", "--env", "CartPole-v1", "--method", "abco", "--run-dir", str(tmp_path / "run"),
            "--expert-data", cfg.expert_data, "--pre-data", cfg.pre_data, "--quiet"]
    other = ["--iterations", "1", "--idm-epochs", "1", "--policy-epochs", "1",
             "--first-epochs-factor", "1", "--eval-layouts", "2", "--eval-episodes", "2",
             "--plot-layouts", "2", "--eval-max-steps", "30", "--no-plots",
             "--schedule", "epochs"]  # fmt: skip
    assert main([*args, *other]) == 2
    err = capsys.readouterr().err
    assert "checkpoint.pt is damaged" in err and err.count("\n") == 1
    ckpt.write_bytes(data)  # the checkpoint back: the cut metrics line does not stop a resume
    assert main([*args, *other]) == 0
    lines = metrics.read_text().splitlines()
    assert [json.loads(x)["iteration"] for x in lines] == [0, 1]
    assert main([*args, *other, "--idm-epochs", "2"]) == 2  # another config: refused
    assert "holds a run of another config" in capsys.readouterr().err


def test_finished_run_answers_from_its_stored_result(tiny_data, tmp_path) -> None:
    cfg = tiny_config("CartPole-v1", "bco", tiny_data, tmp_path / "run")
    first = train(cfg)
    final = tmp_path / "run" / "final.json"
    stamp = final.stat().st_mtime_ns
    assert train(cfg.replace(quiet=False)) == first  # runtime settings may differ
    assert final.stat().st_mtime_ns == stamp  # nothing re-evaluated or rewritten


@pytest.mark.parametrize("env", ["CartPole-v1", "AbcoMaze3x3-v0"])
def test_load_policy_reproduces_the_final_evaluation(tiny_data, tmp_path, env) -> None:
    final = train(tiny_config(env, "abco", tiny_data, tmp_path / "run"))
    policy = abco_train.load_policy(tmp_path / "run")
    again = policy.evaluate()
    drop = ("figures", "seconds", "health")  # health describes the training, not the policy
    assert {k: v for k, v in again.items() if k not in drop} == \
        {k: v for k, v in final.items() if k not in drop}
    space = policy.observation_space
    one = np.zeros(space.shape, dtype=space.dtype)
    assert isinstance(policy(one), int)
    assert policy(np.stack([one] * 3)).shape == (3,)


def test_play_writes_an_animation(tiny_data, tmp_path, capsys) -> None:
    from PIL import Image

    train(tiny_config("AbcoMaze3x3-v0", "bco", tiny_data, tmp_path / "run"))
    out = tmp_path / "play.gif"
    code = main(["play", str(tmp_path / "run"), "--episodes", "0-1", "--max-steps", "5",
                 "--out", str(out), "--quiet"])  # fmt: skip
    assert code == 0 and str(out) in capsys.readouterr().out
    with Image.open(out) as gif:
        assert gif.n_frames >= 4 and min(gif.size) >= 256
    assert main(["play", str(tmp_path / "nothing")]) == 2


def test_device_cpu_is_the_cpu_run(tiny_data, tmp_path) -> None:
    a = train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "a", device="cpu"))
    b = train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "b", device="auto"))
    drop = ("figures", "seconds")
    if not torch.cuda.is_available():  # auto is cpu here: the very same run
        assert {k: v for k, v in a.items() if k not in drop} == \
            {k: v for k, v in b.items() if k not in drop}
    assert json.loads((tmp_path / "a" / "config.json").read_text())["device"] == "cpu"


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA device")
def test_cuda_without_a_gpu_is_refused(tmp_path, capsys) -> None:
    code = main(["train", "--env", "CartPole-v1", "--device", "cuda", "--quiet",
                 "--run-dir", str(tmp_path / "run")])  # fmt: skip
    assert code == 2 and "sees no CUDA device" in capsys.readouterr().err


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("env, method", [("CartPole-v1", "abco"), ("AbcoMaze3x3-v0", "abco"),
                                         ("AbcoMaze3x3-v0", "bco-alpha-torabi"),
                                         ("AbcoMaze3x3-v0", "dilo"), ("AbcoMaze3x3-v0", "lapo")])
def test_cuda_run_resumes_and_loads_on_cpu(tiny_data, tmp_path, env, method) -> None:
    """On a GPU the training data lives there (a maze's frames drawn there); a stopped run
    resumes from its checkpoint, and the policy loads on the CPU."""
    few = {"dilo": {"steps": 4}, "lapo": {"model_steps": 4, "policy_steps": 4}}.get(method, {})
    cfg = tiny_config(env, method, tiny_data, tmp_path / "gpu", device="cuda",
                      method_options=few)  # fmt: skip
    assert train(cfg, stop_after=1) is None
    final = train(cfg)  # resumes from a checkpoint holding CUDA tensors
    assert json.loads((tmp_path / "gpu" / "config.json").read_text())["device"] == "cuda"
    policy = abco_train.load_policy(tmp_path / "gpu")  # on CPU
    assert next(policy.method.policy.parameters()).device.type == "cpu"
    headline = "episodes" if env == "CartPole-v1" else "train/paper"
    assert np.isfinite(final[headline]["performance"])
    assert np.isfinite(policy.evaluate()[headline]["performance"])


def test_data_given_to_the_trainer_is_checked_before_training(tiny_data, tmp_path, capsys):
    import shutil

    import h5py

    expert, pre = tiny_data("CartPole-v1")
    base = ["train", "--env", "CartPole-v1", "--method", "bco", "--quiet", "--iterations", "0"]
    # a pre-demonstration file given as expert data
    assert main([*base, "--expert-data", pre, "--pre-data", pre,
                 "--run-dir", str(tmp_path / "a")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert err.startswith("error: ") and pre in err and "expert" in err
    # one NaN in the observations
    bad = tmp_path / "nan.hdf5"
    shutil.copy(pre, bad)
    with h5py.File(bad, "r+") as f:
        f["observations"][0, 0] = np.nan
    assert main([*base, "--expert-data", expert, "--pre-data", str(bad),
                 "--run-dir", str(tmp_path / "b")]) == 2  # fmt: skip
    assert str(bad) in capsys.readouterr().err
    assert not (tmp_path / "b" / "metrics.jsonl").exists()  # refused before any training
    # an id of the wrong kind
    assert main([*base, "--pre-data", "abco/cartpole-expert-v0",
                 "--run-dir", str(tmp_path / "c")]) == 2  # fmt: skip
    assert "this run needs pre_demonstrations" in capsys.readouterr().err


def test_every_option_names_its_default_once(capsys) -> None:
    from abco_train.cli import main

    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: 10%, at most 2,000)" in text and "%%" not in text
    assert "self-attention in both networks (default: the method's) --batch-size" in text
    assert "(default: |I_pre|) --policy-epochs" in text  # a method option, its default once
