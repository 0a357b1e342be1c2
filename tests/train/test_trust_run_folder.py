"""Run folders you can trust, the trainer's side: one writer per folder (a second refused at
once, naming the holder; a killed holder never blocks), outputs only to regular files or new
paths, JSON read defensively (no FIFO, no endless file, no crafted ``final.json`` counted as a
result), and a full or read-only disk ending a run in one line with nothing lost."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import stat
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any

import matplotlib
import pytest
from train_testing import one_error_line, tiny_config, train_argv

from abco_train.cli import main
from abco_train.harness.loop import train
from abco_train.harness.plots import pyplot, save_figure
from abco_train.harness.run_folder import (
    MAX_JSON_BYTES,
    RunFolderError,
    finished_result,
    read_json,
    write_atomic,
)
from abco_train.harness.run_lock import (
    HOLDER_FILE,
    LOCK_FILE,
    RunFolderInUseError,
    run_folder_lock,
)

matplotlib.use("Agg")
DROP = ("figures", "seconds")


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


# -- JSON read defensively ---------------------------------------------------------------------


@pytest.mark.parametrize(("content", "message"), [
    (b"\xff\xfe{}", "is damaged ('utf-8' codec can't decode"),
    (b"[" * 100_000, "is damaged (nested too deeply)"),
    (b"1" * 5_000, "is damaged (Exceeds the limit"),
    (b'{"a": 1', "is damaged (Expecting"),
])  # fmt: skip
def test_damaged_json_is_one_line(tmp_path, content, message) -> None:
    (tmp_path / "config.json").write_bytes(content)
    with pytest.raises(RunFolderError, match=re.escape(message)) as caught:
        read_json(tmp_path / "config.json")
    assert "\n" not in str(caught.value)


def test_json_that_is_no_file_or_too_large_is_never_read(tmp_path) -> None:
    fifo = tmp_path / "config.json"
    os.mkfifo(fifo)  # a read would wait for a writer forever
    with pytest.raises(RunFolderError, match="is a FIFO .*not a regular file"):
        read_json(fifo)
    endless = tmp_path / "final.json"
    endless.symlink_to("/dev/zero")
    with pytest.raises(RunFolderError, match="is a character device, not a regular file"):
        read_json(endless)
    big = tmp_path / "metrics.json"
    with big.open("wb") as f:
        f.truncate(MAX_JSON_BYTES + 1)  # sparse: nothing to read, all of it refused
    with pytest.raises(RunFolderError, match="holds 67,108,865 bytes, more than the 67,108,864"):
        read_json(big)


# -- crafted final.json and config.json ----------------------------------------------------------


@pytest.fixture
def folder(tiny_data, tmp_path) -> tuple[Any, Path]:
    """A tiny CartPole config and a run folder holding its ``config.json`` (nothing trained)."""
    cfg = tiny_config("CartPole-v1", "bco", tiny_data, tmp_path / "run")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.json").write_text(cfg.to_json())
    return cfg, tmp_path / "run"


_CELL = '"env": "CartPole-v1", "method": "bco", "seed": 0'


@pytest.mark.parametrize(("final", "message"), [
    ("{}", "no status"),
    ("[]", "a JSON list, not an object"),
    ("NaN", "a JSON float, not an object"),
    ('{"status": 1}', "no status"),
    ('{"status": "ok"}', "no env"),
    ('{"status": "ok", "env": "Acrobot-v1"}', "its env is 'Acrobot-v1', not 'CartPole-v1'"),
    ('{"status": "ok", "env": "CartPole-v1", "method": "bco", "seed": true}',
     "its seed is 'True'"),
    ('{"status": "ok", ' + _CELL + '}', "a finished run without any evaluation"),
    ('{"status": "ok", ' + _CELL + ', "episodes": "x"}', "a finished run without any"),
    ('{"status": "ok", ' + _CELL + ', "episodes": {"performance": "high", "aer": 0,'
     ' "success_rate": 1, "episodes": 2}}', "an evaluation without its (finite) numbers"),
    ('{"status": "ok", ' + _CELL + ', "episodes": {"performance": NaN, "aer": 0,'
     ' "success_rate": 1, "episodes": 2}}', "an evaluation without its (finite) numbers"),
    ('{"status": "failed", ' + _CELL + ', "message": ["x"]}', "a failure's message"),
    ('{"status": "failed", ' + _CELL + ', "figures": [1]}', "figures that are not file names"),
    ("[" * 100_000, "nested too deeply"),
])  # fmt: skip
def test_a_crafted_final_json_is_never_a_result(folder, capsys, final, message) -> None:
    cfg, run_dir = folder
    (run_dir / "final.json").write_text(final)
    with pytest.raises(RunFolderError, match=re.escape(message)):
        train(cfg)
    assert main(train_argv(cfg)) == 2
    one_error_line(capsys.readouterr().err, "final.json", message)
    assert (run_dir / "final.json").read_text() == final  # never replaced
    assert not (run_dir / "checkpoint.pt").exists()  # nothing trained


def test_a_finished_record_is_the_result(folder) -> None:
    cfg, run_dir = folder
    failed = {"env": "CartPole-v1", "method": "bco", "seed": 0, "status": "idm_at_chance",
              "message": "the IDM is at chance", "iteration": 0}  # fmt: skip
    (run_dir / "final.json").write_text(json.dumps(failed))
    assert train(cfg) == failed


@pytest.mark.parametrize(("config", "message"), [
    ("[1, 2]", "holds no config (a JSON list)"),
    ("[" * 100_000, "is damaged (nested too deeply)"),
])  # fmt: skip
def test_a_crafted_config_json_is_one_line(folder, config, message) -> None:
    cfg, run_dir = folder
    (run_dir / "config.json").write_text(config)
    (run_dir / "final.json").write_text('{"status": "ok"}')
    with pytest.raises(RunFolderError, match=re.escape(message)):
        train(cfg)
    with pytest.raises(RunFolderError, match=re.escape(message)):
        finished_result(run_dir, asdict(cfg))


def test_a_finished_run_of_another_config_is_never_replaced(folder) -> None:
    cfg, run_dir = folder
    (run_dir / "config.json").write_text(json.dumps({"env": "CartPole-v1", "sneaky": 1}))
    (run_dir / "final.json").write_text('{"status": "ok"}')
    with pytest.raises(RunFolderError, match="holds a run of another config"):
        train(cfg)
    assert (run_dir / "final.json").read_text() == '{"status": "ok"}'


# -- outputs only to regular files or new paths --------------------------------------------------


def test_a_run_folder_that_is_no_folder_is_refused(tiny_data, tmp_path, capsys) -> None:
    cfg = tiny_config("CartPole-v1", "bco", tiny_data, "/dev/null")
    with pytest.raises(RunFolderError, match="run folder /dev/null is a character device"):
        train(cfg)
    assert main(train_argv(cfg)) == 2
    one_error_line(capsys.readouterr().err, "/dev/null is a character device, not a folder")
    file = tmp_path / "notes.txt"
    file.write_text("mine")
    with pytest.raises(RunFolderError, match="is a regular file, not a folder"):
        train(cfg.replace(run_dir=str(file)))
    with pytest.raises(RunFolderError, match="a parent of it is a file"):
        train(cfg.replace(run_dir=str(file / "run")))
    assert file.read_text() == "mine"


def test_what_is_no_regular_file_in_a_run_folder_is_never_replaced(folder) -> None:
    cfg, run_dir = folder
    (run_dir / "config.json").unlink()
    os.mkfifo(run_dir / "config.json")
    with pytest.raises(RunFolderError, match="config.json: it is a FIFO"):
        train(cfg)
    assert stat.S_ISFIFO(os.lstat(run_dir / "config.json").st_mode)
    (run_dir / "config.json").unlink()
    elsewhere = run_dir.parent / "precious.txt"
    elsewhere.write_text("precious")
    (run_dir / "metrics.png").symlink_to(elsewhere)
    with pytest.raises(RunFolderError, match="metrics.png: it is a symbolic link"):
        train(cfg)
    assert elsewhere.read_text() == "precious" and (run_dir / "metrics.png").is_symlink()
    with pytest.raises(RunFolderError, match="it is a symbolic link"):
        write_atomic(run_dir / "metrics.png", "x")
    (run_dir / "metrics.png").unlink()
    (run_dir / LOCK_FILE).symlink_to(elsewhere)  # a lock that would empty the file it names
    with pytest.raises(RunFolderError, match="run.lock: it is a symbolic link"):
        train(cfg)
    assert elsewhere.read_text() == "precious"


# -- one writer per run folder -------------------------------------------------------------------

_HOLD = """
import sys
from abco_train.harness.run_lock import run_folder_lock
with run_folder_lock(sys.argv[1], "abco train"):
    print("locked", flush=True)
    sys.stdin.readline()
"""


def _start(script: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-c", script, *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)  # fmt: skip


def test_a_second_writer_is_refused_at_once_and_a_killed_one_blocks_nothing(tmp_path) -> None:
    holder = _start(_HOLD, str(tmp_path))
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        refusal = (f"is in use by pid {holder.pid} on .* \\(abco train, since .*\\); wait for "
                   "it or use another --run-dir")  # fmt: skip
        with pytest.raises(RunFolderInUseError, match=refusal), \
                run_folder_lock(tmp_path, "abco train"):  # fmt: skip
            pytest.fail("two writers")
    finally:
        holder.kill()  # as a crash would: no release, its holder file left behind
        holder.wait()
    assert (tmp_path / HOLDER_FILE).exists()
    with run_folder_lock(tmp_path, "abco convert-checkpoint"):  # the OS dropped the lock
        assert json.loads((tmp_path / HOLDER_FILE).read_text())["pid"] == os.getpid()
    assert not (tmp_path / HOLDER_FILE).exists() and (tmp_path / LOCK_FILE).exists()


def test_a_holder_file_from_elsewhere_is_read_as_one_short_line(tmp_path) -> None:
    holder = _start(_HOLD, str(tmp_path))
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "locked\n"
        crafted = {"pid": "1\nerror: fake", "host": "h" * 999}
        (tmp_path / HOLDER_FILE).write_text(json.dumps(crafted))
        with pytest.raises(RunFolderInUseError) as caught, run_folder_lock(tmp_path, "x"):
            pass
        assert "\n" not in str(caught.value) and len(str(caught.value)) < 400
        (tmp_path / HOLDER_FILE).write_text("[" * 100_000)
        with pytest.raises(RunFolderInUseError, match="in use by another process"), \
                run_folder_lock(tmp_path, "x"):  # fmt: skip
            pass
    finally:
        holder.kill()
        holder.wait()


_TRAIN_PAUSED = """
import json, sys
from abco_train.harness import loop
from abco_train.methods.registry import config_from_record

save = loop.save_checkpoint
def pause(path, iteration, *args):
    save(path, iteration, *args)
    if iteration == 0:
        print("paused", flush=True)
        sys.stdin.readline()
loop.save_checkpoint = pause
loop.train(config_from_record(json.loads(sys.argv[1])))
print("done", flush=True)
"""


def test_two_trainings_of_one_folder_one_runs_the_other_is_refused(tiny_data, tmp_path,
                                                                     capsys) -> None:  # fmt: skip
    a = tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "run")
    b = a.replace(seed=1)
    first = _start(_TRAIN_PAUSED, json.dumps(asdict(a)))
    try:
        assert first.stdout is not None and first.stdout.readline() == "paused\n"
        with pytest.raises(RunFolderInUseError, match=f"in use by pid {first.pid} "):
            train(b)
        assert main(train_argv(b, method="abco")) == 2
        one_error_line(capsys.readouterr().err, f"in use by pid {first.pid} on ",
                       "(abco train, since")
        assert first.stdin is not None
        first.stdin.write("\n")
        first.stdin.flush()
        assert first.stdout.readline() == "done\n" and first.wait() == 0
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    final = json.loads((tmp_path / "run" / "final.json").read_text())
    assert final["seed"] == 0 and json.loads((tmp_path / "run" / "config.json").read_text())[
        "seed"] == 0
    rows = (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(r)["iteration"] for r in rows] == [0, 1]
    assert train(a) == final  # the folder is the first run's, whole
    with pytest.raises(RunFolderError, match="holds a run of another config"):
        train(b)


# -- full and read-only disks --------------------------------------------------------------------


@pytest.fixture
def small_disk(tmp_path) -> Any:
    """A 64 MiB file system of its own (tmpfs), mounted for the test; skipped where this
    process may not mount one."""
    mount = tmp_path / "disk"
    mount.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a small file system needs root and mount(8)")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64m", "tmpfs", str(mount)],
                          capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        pytest.skip(f"cannot mount a small file system here: {done.stderr.strip()}")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=False)


def _fill(mount: Path, leave: int = 0) -> Path:
    """Fill the file system of ``mount`` but ``leave`` bytes; the filler file."""
    filler = mount / "filler"
    free = os.statvfs(mount).f_bavail * os.statvfs(mount).f_frsize - leave
    with filler.open("wb", buffering=0) as f:
        try:
            while free > 0:
                free -= f.write(b"\0" * min(free, 1 << 20)) or 0
        except OSError as exc:
            assert exc.errno == errno.ENOSPC
    return filler


def test_a_plot_on_a_full_disk_leaves_the_previous_one(small_disk) -> None:
    path = small_disk / "metrics.png"
    path.write_bytes(b"the previous plot")
    _fill(small_disk)
    fig = pyplot().figure()
    fig.gca().plot([0, 1], [1, 0])
    with pytest.raises(OSError) as caught:
        save_figure(fig, path)
    assert caught.value.errno == errno.ENOSPC and caught.value.filename == str(path)
    assert path.read_bytes() == b"the previous plot"
    assert sorted(p.name for p in small_disk.iterdir()) == ["filler", "metrics.png"]


def test_training_on_a_full_disk_ends_in_one_line_and_loses_nothing(
        tiny_data, tmp_path, small_disk, capsys) -> None:  # fmt: skip
    full = train(tiny_config("CartPole-v1", "abco", tiny_data, tmp_path / "full"))
    assert full is not None
    cfg = tiny_config("CartPole-v1", "abco", tiny_data, small_disk / "run")
    assert train(cfg, stop_after=1) is None
    before = _files(small_disk / "run")
    filler = _fill(small_disk, leave=64 * 1024)  # room for the small files, not a checkpoint
    assert main(train_argv(cfg)) == 1
    one_error_line(capsys.readouterr().err, "No space left on device: ", "checkpoint.pt",
              "free some space and run the same command again")
    after = _files(small_disk / "run")
    assert after["checkpoint.pt"] == before["checkpoint.pt"]
    assert sorted(after) == sorted(before) and not (small_disk / "run" / "final.json").exists()
    assert all(data for name, data in after.items() if name != LOCK_FILE)  # no empty files
    filler.unlink()
    assert main(train_argv(cfg)) == 0  # the same command, once there is room: resumed
    final = json.loads((small_disk / "run" / "final.json").read_text())
    assert {k: v for k, v in final.items() if k not in DROP} == \
        {k: v for k, v in full.items() if k not in DROP}  # fmt: skip


def test_a_read_only_run_folder_ends_training_and_play_in_one_line(tiny_data, small_disk,
                                                                    capsys) -> None:  # fmt: skip
    cfg = tiny_config("CartPole-v1", "bco", tiny_data, small_disk / "run", iterations=0)
    train(cfg)
    before = _files(small_disk / "run")
    done = subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], capture_output=True)
    if done.returncode != 0:
        pytest.skip("cannot remount the small file system read-only")
    assert main(train_argv(cfg, method="bco", iterations=0, seed=1)) == 1
    one_error_line(capsys.readouterr().err, "Read-only file system: ", "run.lock")
    assert main(train_argv(cfg, method="bco", iterations=0)) == 0  # finished: its result
    assert "bco on CartPole-v1 (seed 0)" in capsys.readouterr().out
    assert main(["play", str(small_disk / "run"), "--episodes", "0", "--max-steps", "3",
                 "--quiet"]) == 1  # fmt: skip
    one_error_line(capsys.readouterr().err, "Read-only file system: ", "play_train.gif")
    assert _files(small_disk / "run") == before
