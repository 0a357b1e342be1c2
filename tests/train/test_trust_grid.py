"""``abco bench`` you can trust: one writer per grid, bounded plans, crafted records refused,
``--threads`` as its help says, control characters escaped, full and read-only disks.

No cell trains here: the local backend is replaced by one that returns rows at once (in this
process, or in a second process that holds the grid's lock until the test lets it go).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

import pytest

from abco_train.bench import grid as bench
from abco_train.bench.cells import MAX_CELLS
from abco_train.bench.lock import HOLDER_FILE, GridInUseError
from abco_train.bench.records import RecordError
from abco_train.cli import main as abco_main
from abco_train.config.run import ConfigError

#: A fake backend's rows: a finished cell's, built by hand (no training, no dataset).
FAKE_BACKEND = '''
def fake_final(task):
    score = {"performance": 1.0, "aer": 500.0, "success_rate": 1.0, "episodes": 3}
    return {"env": task["env"], "method": task["method"], "seed": task["seed"],
            "status": "ok", "episodes": score}


def fake_row(task, **extra):
    return {"env": task["env"], "method": task["method"], "seed": task["seed"],
            "run_dir": task["run_dir"], "status": "done", "final": fake_final(task),
            "wall_s": 1.5, "threads": task["threads"], "reference": None, **extra}
'''
namespace: dict[str, Any] = {}
exec(FAKE_BACKEND, namespace)  # the same rows in this process as in the holder's
fake_row = namespace["fake_row"]

HOLDER = FAKE_BACKEND + '''
import sys, time
from pathlib import Path
from abco_train.bench import grid as bench

out, ready, go = map(Path, sys.argv[1:4])


def backend(work, tasks, plugins, jobs):
    for i, task in enumerate(tasks):
        if i == 1:  # one row written: hold the lock until the test says go
            ready.touch()
            while not go.exists():
                time.sleep(0.05)
        yield i, fake_row(task)


bench.backends.run_local = backend
bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0, 1, 2]), out, threads=1, jobs=1,
               quiet=True)
'''


def _wait_for(path: Path, process: subprocess.Popen[bytes]) -> None:
    """Wait until ``path`` exists (the holder is inside its session); fail if it died."""
    deadline = time.monotonic() + 300
    while not path.exists():
        if process.poll() is not None:
            raise AssertionError(f"the holder ended ({process.returncode}): "
                                 f"{process.stderr.read().decode() if process.stderr else ''}")
        assert time.monotonic() < deadline, "the holder never took the lock"
        time.sleep(0.05)


def _holder(out: Path, tmp_path: Path) -> tuple[subprocess.Popen[bytes], Path]:
    ready, go = tmp_path / "ready", tmp_path / "go"
    process = subprocess.Popen([sys.executable, "-c", HOLDER, str(out), str(ready), str(go)],
                               stderr=subprocess.PIPE)  # fmt: skip
    _wait_for(ready, process)
    return process, go


@pytest.fixture
def instant(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """The local backend replaced by one returning finished rows at once; the tasks it got."""
    seen: list[dict[str, Any]] = []

    def backend(work: Any, tasks: list[dict[str, Any]], plugins: Any, jobs: int) -> Any:
        for i, task in enumerate(tasks):
            seen.append(task)
            yield i, fake_row(task)

    monkeypatch.setattr(bench.backends, "run_local", backend)
    return seen


def _lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


# -- one writer per grid -------------------------------------------------------------------------


def test_a_second_session_is_refused_and_no_row_is_lost(tmp_path: Path, instant: Any,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:  # fmt: skip
    out = tmp_path / "grid"
    out.mkdir()
    earlier = {"env": "Acrobot-v1", "method": "bc", "seed": 7, "status": "done", "wall_s": 9.0}
    (out / bench.RESULTS_FILE).write_text(json.dumps(earlier) + "\n")
    process, go = _holder(out, tmp_path)
    try:
        held = (out / bench.RESULTS_FILE).read_bytes()
        with pytest.raises(GridInUseError, match=f"in use by pid {process.pid} on "):
            bench.run_grid(bench.plan(["CartPole-v1"], ["abco"], [0, 1]), out, threads=1,
                           quiet=True)  # fmt: skip
        capsys.readouterr()
        code = abco_main(["bench", "--envs", "CartPole-v1", "--methods", "abco", "--seeds",
                          "0-1", "--out", str(out), "--quiet"])  # fmt: skip
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and err.startswith("error: ")
        assert f"pid {process.pid}" in err and "since " in err and "abco" in err
        assert (out / bench.RESULTS_FILE).read_bytes() == held  # the refused wrote nothing
        assert instant == []  # and ran nothing
    finally:
        go.touch()
        assert process.wait(timeout=300) == 0
    assert not (out / HOLDER_FILE).exists()
    # the lock is free again: the next session runs, every row of both kept
    bench.run_grid(bench.plan(["CartPole-v1"], ["abco"], [0, 1]), out, threads=1, quiet=True)
    rows = bench.read_results(out)
    assert sorted(rows) == ["Acrobot-v1/bc/seed7", "CartPole-v1/abco/seed0",
                            "CartPole-v1/abco/seed1", "CartPole-v1/bc/seed0",
                            "CartPole-v1/bc/seed1", "CartPole-v1/bc/seed2"]  # fmt: skip
    assert rows["Acrobot-v1/bc/seed7"] == earlier
    log = _lines(out / bench.BENCH_LOG)
    assert [(s["ran"], s["finished"]) for s in log] == [(3, True), (2, True)]


def test_a_killed_holder_leaves_its_rows_and_no_lock(tmp_path: Path, instant: Any) -> None:
    out = tmp_path / "grid"
    process, _ = _holder(out, tmp_path)
    process.kill()  # mid-session: the operating system drops its lock
    process.wait(timeout=60)
    assert list(bench.read_results(out)) == ["CartPole-v1/bc/seed0"]
    bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0, 1, 2]), out, threads=1, quiet=True)
    assert len(bench.read_results(out)) == 3 and len(instant) == 3  # all rerun but kept once
    log = _lines(out / bench.BENCH_LOG)
    assert [s["finished"] for s in log] == [False, True]


def test_a_holder_file_that_is_a_link_is_refused_and_kept(tmp_path: Path, instant: Any) -> None:
    out = tmp_path / "grid"
    out.mkdir()
    (tmp_path / "elsewhere").write_text("theirs")
    (out / HOLDER_FILE).symlink_to(tmp_path / "elsewhere")
    with pytest.raises(ValueError, match="symbolic link"):  # the writer's one-line refusal
        bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), out, threads=1, quiet=True)
    assert (out / HOLDER_FILE).is_symlink() and (tmp_path / "elsewhere").read_text() == "theirs"
    assert instant == []


def test_a_lock_file_that_is_a_link_is_never_followed(tmp_path: Path, instant: Any) -> None:
    out = tmp_path / "grid"
    out.mkdir()
    (tmp_path / "precious").write_text("theirs")
    (out / "bench.lock").symlink_to(tmp_path / "precious")
    with pytest.raises(ValueError, match="symbolic link"):
        bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), out, threads=1, quiet=True)
    assert (tmp_path / "precious").read_text() == "theirs" and instant == []


def test_an_out_that_is_not_a_folder_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    import stat

    code = abco_main(["bench", "--envs", "CartPole-v1", "--methods", "bc", "--seeds", "0",
                      "--out", "/dev/null", "--quiet"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and err == "error: --out /dev/null is not a folder\n"
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


# -- bounds ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("text", "message"), [
    ("0-99999999999", "out of range"), ("0-2147483648", "out of range"),
    ("0-2000000", f"more than {MAX_CELLS:,}"),
    ("1" * 5000, "out of range"), ("٣", "bad seed range"), ("seed3", "bad seed range"),
    ("²", "bad seed range"), ("-1", "bad seed range"), ("4-2", "empty"), ("", "no seeds"),
])  # fmt: skip
def test_seeds_are_bounded_before_any_list_is_built(text: str, message: str) -> None:
    tracemalloc.start()
    try:
        with pytest.raises(ConfigError, match=message):
            bench.parse_seeds(text)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000  # refused before the range's list (millions of ints) was made


def test_seeds_in_the_millions_and_at_the_limit_work() -> None:
    assert bench.parse_seeds("2147483600-2147483647")[-1] == 2**31 - 1
    assert bench.parse_seeds("5000000,0-2") == [5_000_000, 0, 1, 2]
    assert len(bench.parse_seeds(f"0-{MAX_CELLS - 1}")) == MAX_CELLS
    with pytest.raises(ConfigError, match=f"more than {MAX_CELLS:,}"):
        bench.parse_seeds(f"0-{MAX_CELLS - 1},{MAX_CELLS}")


@pytest.mark.parametrize(("text", "message"), [
    ("100000", "out of range"), ("0", "out of range"), ("²", "bad --layouts"),
    ("10k", "bad --layouts"), ("100-200", "bad --layouts"), (",", "no --layouts"),
])  # fmt: skip
def test_layouts_are_bounded(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        bench.parse_layouts(text)


def test_a_grid_is_bounded_before_its_cells_are_made() -> None:
    tracemalloc.start()
    try:
        with pytest.raises(ConfigError, match="a grid holds at most 100,000"):
            bench.plan([f"env{i}" for i in range(100)], [f"m{i}" for i in range(100)],
                       range(100))  # fmt: skip
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000


@pytest.mark.parametrize(("flag", "value", "message"), [
    ("--envs", "", "no --envs given"), ("--methods", " , ", "no --methods given"),
    ("--seeds", "0-99999999999", "out of range"), ("--envs", "../../etc", "not a valid name"),
    ("--layouts", "²", "bad --layouts"),
])  # fmt: skip
def test_bench_refuses_an_empty_or_unbounded_grid(tmp_path: Path, flag: str, value: str,
                                                 message: str,
                                                 capsys: pytest.CaptureFixture[str]
                                                 ) -> None:  # fmt: skip
    args = {"--envs": "AbcoMaze5x5-v0", "--methods": "bc", "--seeds": "0",
            "--out": str(tmp_path / "grid"), flag: value}  # fmt: skip
    code = abco_main(["bench", "--quiet", *[x for kv in args.items() for x in kv]])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "grid").exists()


# -- crafted records -----------------------------------------------------------------------------


CRAFTED_FINALS = {
    "empty object": "{}",
    "a list": "[]",
    "truncated": '{"env": "CartPole-v1", "method": "bc", "se',
    "NaN performance": '{"env": "CartPole-v1", "method": "bc", "seed": 0, "status": "ok",'
                       ' "episodes": {"performance": NaN, "aer": 1.0}}',
    "another cell's": '{"env": "CartPole-v1", "method": "abco", "seed": 0, "status": "ok",'
                      ' "episodes": {"performance": 1.0, "aer": 1.0}}',
    "no evaluation": '{"env": "CartPole-v1", "method": "bc", "seed": 0, "status": "ok"}',
    "nested too deeply": "[" * 100_000 + "]" * 100_000,
    "not UTF-8": b'{"env": "\xff"}',
}


@pytest.mark.parametrize("kind", sorted(CRAFTED_FINALS))
def test_a_crafted_finished_cell_is_never_reused(tmp_path: Path, instant: Any,
                                                 kind: str) -> None:  # fmt: skip
    out = tmp_path / "grid"
    run_dir = out / "CartPole-v1" / "bc" / "seed0"
    run_dir.mkdir(parents=True)
    data = CRAFTED_FINALS[kind]
    (run_dir / "final.json").write_bytes(data if isinstance(data, bytes) else data.encode())
    with pytest.raises(RecordError, match="seed0/final.json is not a finished run's record"):
        bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0, 1]), out, threads=1, quiet=True)
    assert instant == [] and not (out / bench.RESULTS_FILE).exists()
    assert sorted(p.name for p in run_dir.iterdir()) == ["final.json"]


@pytest.mark.parametrize("kind", ["folder", "/dev/zero", "fifo"])
def test_a_final_json_that_is_not_a_file_is_refused_unread(tmp_path: Path, instant: Any,
                                                           kind: str) -> None:  # fmt: skip
    out = tmp_path / "grid"
    run_dir = out / "CartPole-v1" / "bc" / "seed0"
    run_dir.mkdir(parents=True)
    final = run_dir / "final.json"
    if kind == "folder":
        final.mkdir()
    elif kind == "fifo":
        os.mkfifo(final)
    else:
        final.symlink_to("/dev/zero")
    with pytest.raises(RecordError, match="not a regular file"):
        bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), out, threads=1, quiet=True)
    assert instant == []


def test_a_damaged_results_file_stops_the_grid_untouched(tmp_path: Path, instant: Any) -> None:
    out = tmp_path / "grid"
    out.mkdir()
    good = json.dumps({"env": "CartPole-v1", "method": "bc", "seed": 3, "status": "done"})
    for bad in ('{"env": "CartPole-v1", "meth', '{"method": "bc", "seed": 0, "status": "done"}',
                json.dumps({"env": "CartPole-v1", "method": "bc", "seed": 1e400,
                            "status": "done"})):  # fmt: skip
        (out / bench.RESULTS_FILE).write_text(f"{good}\n{bad}\n")
        with pytest.raises(RecordError, match="results.jsonl line 2: .*repair or remove"):
            bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), out, threads=1, quiet=True)
        assert (out / bench.RESULTS_FILE).read_text() == f"{good}\n{bad}\n"
    assert instant == []


def test_other_lines_of_the_bench_log_are_kept_as_they_are(tmp_path: Path, instant: Any) -> None:
    out = tmp_path / "grid"
    out.mkdir()
    foreign = ['{"wall_s": NaN}', "not json at all", '{"started": "x", "wall_s": 3.0}']
    (out / bench.BENCH_LOG).write_text("\n".join(foreign) + "\n")
    bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), out, threads=1, quiet=True)
    lines = (out / bench.BENCH_LOG).read_text().splitlines()
    assert lines[:3] == foreign and json.loads(lines[3])["ran"] == 1


# -- frictions -------------------------------------------------------------------------------------


def test_threads_default_to_the_cores_over_the_jobs(
    tmp_path: Path, instant: list[dict[str, Any]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """jobs x threads fill the cores: 8 cores, 1 job -> 8 threads, 2 jobs -> 4; --threads wins."""
    monkeypatch.setattr(bench.backends, "available_cores", lambda: 8)
    bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), tmp_path / "a", jobs=1, quiet=True)
    assert abco_main(["bench", "--envs", "CartPole-v1", "--methods", "bc", "--seeds", "1",
                      "--out", str(tmp_path / "b"), "--quiet", "--jobs", "2"]) == 0  # fmt: skip
    bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [2]), tmp_path / "c", threads=3,
                   quiet=True)  # fmt: skip
    assert [t["threads"] for t in instant] == [8, 4, 3]
    assert _lines(tmp_path / "a" / bench.BENCH_LOG)[0]["threads"] == 8


def test_a_failed_cells_message_cannot_forge_a_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]
                                                   ) -> None:  # fmt: skip
    def failing(work: Any, tasks: list[dict[str, Any]], plugins: Any, jobs: int) -> Any:
        yield 0, {**fake_row(tasks[0]), "status": "failed", "final": None,
                  "error": "RuntimeError: boom\nerror: forged\x1b[2K"}  # fmt: skip

    monkeypatch.setattr(bench.backends, "run_local", failing)
    summary = bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), tmp_path, threads=1)
    out = capsys.readouterr().out
    assert not any(x.startswith("error: forged") for x in out.splitlines())
    assert "boom\\nerror: forged\\x1b[2K" in out and "\x1b" not in out
    line = bench.failed_text(summary)  # the one line a command says about failed cells
    assert line.startswith("1 of 1 cells failed: CartPole-v1/bc/seed0 (RuntimeError: boom\\n")
    assert "\n" not in line and line.endswith(f"every cell's error is in {tmp_path}/results.jsonl")


def test_ray_that_cannot_start_is_one_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                            ) -> None:  # fmt: skip
    import types

    def init(**kwargs: Any) -> None:
        raise Exception("The current node timed out during startup.\nThis could happen ...")

    fake = types.SimpleNamespace(is_initialized=lambda: False, init=init)
    monkeypatch.setitem(sys.modules, "ray", fake)
    with pytest.raises(bench.backends.BackendError, match="Ray could not start .*timed out"):
        bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0]), tmp_path, backend="ray",
                       threads=1, quiet=True)  # fmt: skip


# -- full and read-only disks -------------------------------------------------------------------


def _mount_tmpfs(where: Path, size: str) -> None:
    where.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                          capture_output=True)  # fmt: skip
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.decode().strip()})")


@pytest.fixture
def small_disk(tmp_path: Path) -> Any:
    """A 256 KiB tmpfs (skipped where mounting is not allowed), unmounted afterwards."""
    mnt = tmp_path / "mnt"
    _mount_tmpfs(mnt, "256k")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_read_only_grid_is_one_error_with_its_files_intact(small_disk: Path,
                                                             instant: Any) -> None:  # fmt: skip
    out = small_disk / "grid"
    out.mkdir()
    row = json.dumps({"env": "CartPole-v1", "method": "bc", "seed": 0, "status": "done"}) + "\n"
    (out / bench.RESULTS_FILE).write_text(row)
    subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], check=True)
    with pytest.raises(OSError) as raised:
        bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0, 1]), out, threads=1, quiet=True)
    assert raised.value.errno in (30, 13)  # EROFS (or EACCES)
    assert (out / bench.RESULTS_FILE).read_text() == row and instant == []


def test_a_full_disk_keeps_the_results_as_they_were(small_disk: Path, instant: Any) -> None:
    out = small_disk / "grid"
    out.mkdir()
    rows = "".join(json.dumps({"env": "Acrobot-v1", "method": "bc", "seed": s,
                               "status": "done", "pad": "x" * 2000}) + "\n" for s in range(20))
    (out / bench.RESULTS_FILE).write_text(rows)
    with pytest.raises(OSError), (small_disk / "filler").open("wb") as f:  # fill the disk
        while True:
            f.write(b"\0" * 4096)
            f.flush()
    with pytest.raises(OSError) as raised:
        bench.run_grid(bench.plan(["CartPole-v1"], ["bc"], [0, 1]), out, threads=1, quiet=True)
    assert raised.value.errno == 28  # ENOSPC
    assert (out / bench.RESULTS_FILE).read_text() == rows
    left = sorted(p.name for p in out.iterdir())
    assert [p for p in left if p not in (bench.RESULTS_FILE, "bench.lock")] == []
    assert not [p for p in out.iterdir() if p.stat().st_size == 0 and p.name != "bench.lock"]

