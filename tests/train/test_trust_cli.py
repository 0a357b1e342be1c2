"""The ``abco`` command you can trust: every count and size bounded and refused in one line
before any work; plugins that register nothing refused; disk errors (a full disk, a read-only
folder) one line and exit code 1, programming errors still a traceback; a closed stdout quiet;
``abco play`` bounded, and clear about pygame."""

from __future__ import annotations

import errno
import os
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from abco_data.errors import DatasetWriteError
from abco_train.cli import build_parser, main
from abco_train.config import limits
from abco_train.config.run import RunConfig
from abco_train.methods.registry import PluginError, load_plugins

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE_PLUGIN = ROOT / "docs" / "examples" / "my_method.py"


def _one_error_line(err: str, *needles: str) -> None:
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in err, err


@pytest.fixture
def no_training(monkeypatch: pytest.MonkeyPatch) -> None:
    """The trainer, the grid and the GIF writer fail the test if a command reaches them."""

    def started(*args: Any, **kwargs: Any) -> None:
        pytest.fail("work started before the input was checked")

    monkeypatch.setattr("abco_train.harness.loop.train", started)
    monkeypatch.setattr("abco_train.bench.grid.run_grid", started)
    monkeypatch.setattr("abco_train.harness.trained_policy.load_policy", started)
    monkeypatch.setattr("abco_train.harness.trained_policy.record_gif", started)


# -- bounds of the run config ------------------------------------------------------------------


BOUNDS = [
    (["--seed", str(2**31)], "--seed must be <= 2,147,483,647, got 2147483648"),
    (["--seed", "99999999999999999999999"], "--seed must be <= 2,147,483,647"),
    (["--threads", "100000"], "--threads must be <= 256, got 100000"),
    (["--iterations", "1001"], "--iterations must be <= 1,000"),
    (["--batch-size", "65537"], "--batch-size must be <= 65,536"),
    (["--pre-transitions", "100000001"], "--pre-transitions must be <= 100,000,000"),
    (["--expert-episodes", "1000001"], "--expert-episodes must be <= 1,000,000"),
    (["--eval-episodes", "10001"], "--eval-episodes must be <= 10,000"),
    (["--eval-layouts", "10001"], "--eval-layouts must be <= 10,000"),
    (["--eval-max-steps", "10001"], "--eval-max-steps must be <= 10,000"),
    (["--plot-layouts", "101"], "--plot-layouts must be <= 100"),
    (["--lr", "nan"], "--lr must be a finite number, got nan"),
    (["--lr", "inf"], "--lr must be a finite number, got inf"),
    (["--lr=-inf"], "--lr must be a finite number"),
    (["--method-options", '{"bogus": 1}'], "unknown abco option(s) bogus"),
]


@pytest.mark.parametrize(("option", "message"), BOUNDS)
def test_train_refuses_each_bound_in_one_line_before_any_work(tmp_path, capsys, no_training,
                                                              option, message) -> None:  # fmt: skip
    run_dir = tmp_path / "run"
    code = main(["train", "--env", "CartPole-v1", "--quiet", "--run-dir", str(run_dir), *option])
    assert code == 2
    _one_error_line(capsys.readouterr().err, message)
    assert not run_dir.exists()


@pytest.mark.parametrize(("option", "message"), BOUNDS[:4])
def test_bench_refuses_each_bound_before_any_work(tmp_path, capsys, no_training, option,
                                                  message) -> None:  # fmt: skip
    if option[0] == "--seed":  # a grid's seeds are --seeds
        option = ["--seeds", option[1]]
        message = "out of range"
    out = tmp_path / "grid"
    code = main(["bench", "--envs", "CartPole-v1", "--methods", "bc", "--out", str(out),
                 "--quiet", *option])  # fmt: skip
    assert code == 2
    _one_error_line(capsys.readouterr().err, message)
    assert not out.exists()


def test_every_bound_itself_is_accepted() -> None:
    config = RunConfig(
        env="CartPole-v1", seed=limits.MAX_SEED, threads=limits.MAX_THREADS,
        iterations=limits.MAX_ITERATIONS, batch_size=limits.MAX_BATCH_SIZE,
        pre_transitions=limits.MAX_PRE_TRANSITIONS, expert_episodes=limits.MAX_EXPERT_EPISODES,
        eval_episodes=limits.MAX_EVAL_EPISODES, eval_max_steps=limits.MAX_EVAL_MAX_STEPS,
        plot_layouts=limits.MAX_PLOT_LAYOUTS,
    )  # fmt: skip
    assert config.validate() is config


@pytest.mark.parametrize("argv", [
    ["bench", "--envs", "CartPole-v1", "--methods", "bc", "--out", "x", "--jobs", "257"],
    ["bench", "--envs", "CartPole-v1", "--methods", "bc", "--out", "x", "--jobs", "0"],
    ["play", "run", "--fps", "51"],
    ["play", "run", "--max-steps", "1001"],
    ["play", "run", "--max-steps", "many"],
])  # fmt: skip
def test_command_line_counts_are_bounded_by_the_parser(capsys, argv) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {argv[-2]}" in err and "Traceback" not in err


# -- plugins -----------------------------------------------------------------------------------


def test_a_plugin_that_registers_nothing_is_refused(tmp_path, capsys, no_training) -> None:
    plugin = tmp_path / "empty_plugin.py"
    plugin.write_text("VALUE = 1\n")
    for _ in range(2):  # the second time it is imported already: still refused
        code = main(["train", "--env", "CartPole-v1", "--quiet", "--plugin", str(plugin),
                     "--run-dir", str(tmp_path / "run")])  # fmt: skip
        assert code == 2
        _one_error_line(capsys.readouterr().err, f"plugin {plugin} registered no method")
    with pytest.raises(PluginError, match="plugin json registered no method"):
        load_plugins(["json"])  # a module that is no plugin


def test_importing_the_built_in_methods_is_not_registering(tmp_path) -> None:
    plugin = tmp_path / "builtins_only.py"
    plugin.write_text("import abco_train.methods.bco.family\nimport abco_train.methods.iupe\n")
    with pytest.raises(PluginError, match="registered no method"):
        load_plugins([str(plugin)])


def test_a_plugin_that_registers_loads_again_and_again() -> None:
    load_plugins([str(EXAMPLE_PLUGIN)])
    load_plugins([str(EXAMPLE_PLUGIN)])  # imported once; its methods still known


def test_a_plugin_missing_a_dependency_is_not_called_missing(tmp_path, monkeypatch) -> None:
    package = tmp_path / "trust_cli_plugin_pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "broken.py").write_text("import no_such_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(PluginError, match="trust_cli_plugin_pkg.broken failed to import: "
                       "ModuleNotFoundError: No module named 'no_such_dependency_xyz'"):
        load_plugins(["trust_cli_plugin_pkg.broken"])
    with pytest.raises(PluginError, match="plugin module 'trust_cli_plugin_pkg.nope' not found"):
        load_plugins(["trust_cli_plugin_pkg.nope"])


# -- failed operations: one line, exit code 1 ----------------------------------------------------


def _raiser(exc: BaseException) -> Any:
    def raise_it(*args: Any, **kwargs: Any) -> None:
        raise exc

    return raise_it


@pytest.mark.parametrize(("target", "argv"), [
    ("abco_train.harness.loop.train", ["train", "--env", "CartPole-v1", "--quiet"]),
    ("abco_train.bench.grid.run_grid", ["bench", "--envs", "CartPole-v1", "--methods", "bc",
                                        "--out", "OUT", "--quiet"]),
    ("abco_train.report.write.write_report", ["report", "OUT"]),
    ("abco_train.harness.trained_policy.load_policy", ["play", "OUT"]),
])  # fmt: skip
@pytest.mark.parametrize(("code", "reason"), [
    (errno.ENOSPC, "No space left on device"),
    (errno.EROFS, "Read-only file system"),
    (errno.EACCES, "Permission denied"),
    (errno.EPERM, "Operation not permitted"),
])  # fmt: skip
def test_a_disk_error_is_one_line_and_exit_1(tmp_path, capsys, monkeypatch, target, argv, code,
                                             reason) -> None:  # fmt: skip
    where = str(tmp_path / "runs" / "checkpoint.pt")
    monkeypatch.setattr(target, _raiser(OSError(code, os.strerror(code), where)))
    argv = [str(tmp_path) if a == "OUT" else a for a in argv]
    assert main(argv) == 1
    err = capsys.readouterr().err
    _one_error_line(err, f"error: {reason}: {where}")
    assert ("free some space" in err) == (code == errno.ENOSPC)


def test_a_dataset_that_cannot_be_written_is_a_failed_operation(capsys, monkeypatch) -> None:
    monkeypatch.setattr("abco_train.harness.loop.train",
                        _raiser(DatasetWriteError("cannot write /cache/x.hdf5: disk full")))
    assert main(["train", "--env", "CartPole-v1", "--quiet"]) == 1
    _one_error_line(capsys.readouterr().err, "cannot write /cache/x.hdf5: disk full")


@pytest.mark.parametrize("bug", [OSError("an OSError without an errno"), TypeError("a bug"),
                                 KeyError("a bug")])  # fmt: skip
def test_programming_errors_keep_their_traceback(monkeypatch, bug) -> None:
    monkeypatch.setattr("abco_train.harness.loop.train", _raiser(bug))
    with pytest.raises(type(bug)):
        main(["train", "--env", "CartPole-v1", "--quiet"])


def test_a_closed_stdout_ends_quietly(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setattr("abco_train.report.write.write_report",
                        lambda *a, **k: {"report": "r.md", "csv": "r.csv"})  # fmt: skip
    read, write = os.pipe()
    os.close(read)  # the reader went away (abco report ... | head, head done)
    with open(write, "w") as closed:
        monkeypatch.setattr(sys, "stdout", closed)
        assert main(["report", str(tmp_path)]) == 141
        monkeypatch.undo()
    assert capsys.readouterr().err == ""


def test_a_broken_pipe_elsewhere_is_a_failed_operation(capsys, monkeypatch) -> None:
    monkeypatch.setattr("abco_train.harness.loop.train",
                        _raiser(BrokenPipeError(errno.EPIPE, "Broken pipe")))
    assert main(["train", "--env", "CartPole-v1", "--quiet"]) == 1  # stdout is fine
    _one_error_line(capsys.readouterr().err, "error: Broken pipe")


# -- abco play ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("argv", "message"), [
    (["--episodes", "0-99999999999"], "asks for 100,000,000,000 episodes; a GIF holds at most"),
    (["--episodes", "0-99"], "may make 20,500 frames, more than the 5,000"),
    (["--episodes", "0-9", "--max-steps", "1000"], "lower --max-steps"),
    (["--out", "animation.png"], "--out must name a .gif file"),
])  # fmt: skip
def test_play_is_bounded_before_any_work(tmp_path, capsys, no_training, argv, message) -> None:
    assert main(["play", str(tmp_path / "run"), *argv]) == 2
    _one_error_line(capsys.readouterr().err, message)


def _fake_policy(monkeypatch: pytest.MonkeyPatch, env: str) -> list[Any]:
    """``load_policy`` hands back a policy of ``env``; the GIF writer records its calls."""
    calls: list[Any] = []
    policy = SimpleNamespace(config=SimpleNamespace(env=env))
    monkeypatch.setattr("abco_train.harness.trained_policy.load_policy", lambda *a, **k: policy)
    monkeypatch.setattr("abco_train.harness.trained_policy.record_gif",
                        lambda *a, **k: calls.append((a, k)) or Path(a[1]))  # fmt: skip
    return calls


def test_play_without_pygame_names_the_extra(tmp_path, capsys, monkeypatch) -> None:
    calls = _fake_policy(monkeypatch, "CartPole-v1")
    monkeypatch.setitem(sys.modules, "pygame", None)  # not installed
    assert main(["play", str(tmp_path), "--episodes", "0-1"]) == 2
    _one_error_line(capsys.readouterr().err, "pygame", 'pip install "abco[human]"')
    assert calls == []


def test_play_refuses_a_layout_past_the_split(tmp_path, capsys, monkeypatch) -> None:
    calls = _fake_policy(monkeypatch, "AbcoMaze3x3-v0")
    assert main(["play", str(tmp_path), "--episodes", "0,150", "--split", "test"]) == 2
    _one_error_line(capsys.readouterr().err, "the test split of AbcoMaze3x3-v0 has layouts 0-",
                    "got 150")
    assert calls == []


def test_play_draws_off_screen(tmp_path, capsys, monkeypatch) -> None:
    calls = _fake_policy(monkeypatch, "CartPole-v1")
    monkeypatch.delenv("SDL_VIDEODRIVER", raising=False)
    assert main(["play", str(tmp_path), "--episodes", "0-1", "--quiet"]) == 0
    assert os.environ["SDL_VIDEODRIVER"] == "dummy"  # no display needed, none complained about
    assert calls[0][0][2] == [0, 1] and capsys.readouterr().err == ""


# -- abco convert-checkpoint ---------------------------------------------------------------------


def test_convert_checkpoint_says_whom_it_is_for(capsys) -> None:
    with pytest.raises(SystemExit):
        build_parser(["convert-checkpoint", "--help"]).parse_args(["convert-checkpoint", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "only for run folders you trust: the old format can run code" in text


def test_convert_checkpoint_calls_the_converter(tmp_path, capsys, monkeypatch) -> None:
    seen: list[Any] = []
    monkeypatch.setattr("abco_train.harness.checkpoint.convert_legacy_checkpoint",
                        lambda run_dir: seen.append(run_dir) or Path(run_dir) / "checkpoint.pt")
    assert main(["convert-checkpoint", str(tmp_path)]) == 0
    assert seen == [str(tmp_path)]
    assert str(tmp_path / "checkpoint.pt") in capsys.readouterr().out


def test_convert_checkpoint_of_a_folder_without_one_is_one_line(tmp_path, capsys) -> None:
    assert main(["convert-checkpoint", str(tmp_path)]) == 2
    _one_error_line(capsys.readouterr().err, "holds no checkpoint.pt")
