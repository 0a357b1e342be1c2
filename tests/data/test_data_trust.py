"""Outputs, files and parameters abco can trust: special files are never replaced, a dataset
replaced on disk is never mixed with its old index, every creation parameter is bounded, and
the command line stays quiet and short (broken pipes, repr, progress in a log)."""

from __future__ import annotations

import os
import pickle
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from data_testing import make_small, small_overrides

import abco_data
from abco_data import cli, progress
from abco_data.errors import (
    DatasetChangedError,
    DatasetReadError,
    InvalidParameterError,
    InvalidTargetError,
)
from abco_data.format import files
from abco_data.format.files import atomic_target, check_target, file_digest
from abco_data.generation.bounds import COUNT_BOUNDS, MAX_FRAME_BYTES, check_params

PRE = "abco/maze3x3-pre-v0"


def _generate_args(out: Path | str, *extra: str) -> list[str]:
    sets = [f"--set={key}={value}" for key, value in small_overrides(PRE).items()]
    return ["generate", PRE, "--out", str(out), "--quiet", *sets, *extra]


@pytest.fixture
def no_generation(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if generation does any work (refusals come first)."""

    def forbidden(*args: object, **kwargs: object) -> None:
        raise AssertionError("generation started although its input was refused")

    generation = sys.modules["abco_data.generation.generate"]  # abco_data.generate: the function
    monkeypatch.setattr(generation, "reference_for", forbidden)
    monkeypatch.setattr(generation, "DatasetWriter", forbidden)


# --------------------------------------------------------------------------- output paths


def _special_targets(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """name -> (path, what the message calls it); each made fresh in tmp_path."""
    fifo = tmp_path / "fifo.hdf5"
    os.mkfifo(fifo)
    folder = tmp_path / "folder.hdf5"
    folder.mkdir()
    (folder / "keep.txt").write_text("kept")
    real = tmp_path / "real.hdf5"
    real.write_bytes(b"the link's target")
    link = tmp_path / "link.hdf5"
    link.symlink_to(real)
    dangling = tmp_path / "dangling.hdf5"
    dangling.symlink_to(tmp_path / "nowhere.hdf5")
    return {"fifo": (fifo, "a FIFO (named pipe)"), "folder": (folder, "a folder"),
            "link": (link, f"a symbolic link (to {real})"),
            "dangling": (dangling, f"a symbolic link (to {tmp_path / 'nowhere.hdf5'})")}


def _snapshot(tmp_path: Path) -> dict[str, tuple[int, bytes | None]]:
    """Kind and contents of everything in tmp_path (links not followed)."""
    out: dict[str, tuple[int, bytes | None]] = {}
    for path in sorted(tmp_path.rglob("*")):
        mode = path.lstat().st_mode
        data = path.read_bytes() if stat.S_ISREG(mode) else None
        out[str(path.relative_to(tmp_path))] = (stat.S_IFMT(mode), data)
    return out


@pytest.mark.parametrize("name", ["fifo", "folder", "link", "dangling"])
def test_generate_refuses_a_special_output_and_leaves_it_untouched(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, no_generation: None
) -> None:
    target, what = _special_targets(tmp_path)[name]
    before = _snapshot(tmp_path)
    assert cli.main(_generate_args(target)) == cli.EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err == (f"error: cannot write {target}: it is {what}; abco writes only to a new path"
                   " or a regular file, which it replaces\n")
    assert _snapshot(tmp_path) == before
    with pytest.raises(InvalidTargetError):
        abco_data.generate(PRE, target, progress=False, **small_overrides(PRE))
    assert _snapshot(tmp_path) == before


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="only root can replace /dev/full")
def test_root_cannot_replace_dev_full(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], no_generation: None
) -> None:
    real_replace = os.replace

    def guarded(src: object, dst: object) -> None:  # never let a broken check hurt the machine
        assert os.path.abspath(str(dst)) != "/dev/full", "/dev/full was about to be replaced"
        real_replace(src, dst)  # pyright: ignore[reportArgumentType]

    monkeypatch.setattr(files.os, "replace", guarded)
    assert cli.main(_generate_args("/dev/full")) == cli.EXIT_BAD_INPUT
    assert "it is a character device" in capsys.readouterr().err
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_atomic_target_checks_again_before_the_rename(tmp_path: Path) -> None:
    target = tmp_path / "out.json"
    with pytest.raises(InvalidTargetError, match="FIFO"), atomic_target(target) as tmp:
        tmp.write_text("new")
        os.mkfifo(target)  # something took the name while the block ran
    assert stat.S_ISFIFO(target.lstat().st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]  # no temporary left


def test_atomic_target_replaces_regular_files_and_folders_only_as_asked(tmp_path: Path) -> None:
    target = tmp_path / "a.txt"
    target.write_text("old")
    with atomic_target(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"
    folder = tmp_path / "export"
    folder.mkdir()
    with pytest.raises(InvalidTargetError, match="it is a folder"):
        check_target(folder)
    with atomic_target(folder, folder=True) as tmp:
        tmp.mkdir()
        (tmp / "x").write_text("x")
    assert sorted(p.name for p in folder.iterdir()) == ["x"]
    with pytest.raises(InvalidTargetError, match="a new path or a folder"):
        check_target(target, folder=True)


def test_file_digest_never_waits_on_a_fifo(tmp_path: Path) -> None:
    fifo = tmp_path / "x.hdf5"
    os.mkfifo(fifo)
    with pytest.raises(DatasetReadError, match="cannot read a FIFO"):  # not a hang
        file_digest(fifo)


# --------------------------------------------------------------------------- swapped files


@pytest.fixture(scope="module")
def two_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two valid datasets of the same id with different contents."""
    folder = tmp_path_factory.mktemp("swap")
    first = make_small(PRE, folder, "first.hdf5")
    second = make_small(PRE, folder, "second.hdf5", seed=7)
    return first, second


def _loader(view: object) -> object:
    from torch.utils.data import DataLoader

    return DataLoader(view, batch_size=16, num_workers=2,  # pyright: ignore[reportArgumentType]
                      multiprocessing_context="fork")


def test_workers_refuse_a_file_replaced_on_disk(
    tmp_path: Path, two_files: tuple[Path, Path]
) -> None:
    pytest.importorskip("torch")
    first, second = two_files
    path = tmp_path / "data.hdf5"
    path.write_bytes(first.read_bytes())
    view = abco_data.open_dataset(path).torch_dataset()
    items = [batch for batch in _loader(view)]  # type: ignore[attr-defined]
    assert sum(len(b[1]) for b in items) == len(view)  # untouched: every item
    np.testing.assert_array_equal(np.concatenate([b[1].numpy() for b in items]),
                                  abco_data.open_dataset(first).load_arrays().actions)

    swapped = tmp_path / "incoming.hdf5"
    swapped.write_bytes(second.read_bytes())
    os.replace(swapped, path)  # another valid dataset takes the name, as a writer would
    with pytest.raises(DatasetChangedError) as info:
        list(_loader(view))  # type: ignore[call-overload]
    message = str(info.value)
    assert message.startswith(f"{path} changed on disk after it was opened")
    assert "\n" not in message  # one line, although it comes from a worker


def test_the_pin_travels_with_the_view(tmp_path: Path, two_files: tuple[Path, Path]) -> None:
    pytest.importorskip("torch")
    first, second = two_files
    path = tmp_path / "data.hdf5"
    path.write_bytes(first.read_bytes())
    ds = abco_data.open_dataset(path)
    view = ds.torch_dataset()
    view[0]  # this process's handles are open now
    copy = pickle.loads(pickle.dumps(view))  # as a spawned worker gets it: no handle
    path.write_bytes(second.read_bytes())  # rewritten in place: same inode, new bytes
    with pytest.raises(DatasetChangedError, match="changed on disk"):
        copy[0]
    with pytest.raises(DatasetChangedError, match="changed on disk"):
        view[0]  # an open handle notices too
    with pytest.raises(DatasetChangedError, match="changed on disk"):
        ds.load_arrays()
    reopened = abco_data.open_dataset(path)  # opened anew: the new file, whole
    assert reopened.load_arrays().rewards.shape == (reopened.num_transitions,)


# --------------------------------------------------------------------------- bounds


def test_the_standard_datasets_are_within_their_bounds() -> None:
    for dataset_id in abco_data.DATASET_IDS:
        s = abco_data.spec(dataset_id)
        check_params(s.id, s.env_id, s.kind, s.params)


@pytest.mark.parametrize(("dataset_id", "override", "message"), [
    ("abco/maze3x3-pre-v0", "layouts=-1", "layouts=-1 is out of range: from 1 to 100"),
    ("abco/maze3x3-pre-v0", "layouts=101", "layouts=101 is out of range"),
    ("abco/maze5x5-procedural-pre-v0", "layouts=10001", "from 1 to 10000 (the layouts of the"
     " 'procedural' split)"),
    ("abco/cartpole-pre-v0", "transitions=1000000000000", "transitions=1000000000000 is out of"
     " range: from 1 to 10000000"),
    ("abco/cartpole-pre-v0", "transitions=0", "transitions=0 is out of range"),
    ("abco/cartpole-pre-v0", "transitions=1.5", "transitions must be an integer"),
    ("abco/cartpole-expert-v0", "episodes=100000", "from 1 to 20000 (500-step episodes"),
    ("abco/cartpole-expert-v0", "reference_episodes=-1", "reference_episodes=-1 is out of range"),
    ("abco/cartpole-expert-v0", "reference_expert_episodes=10001", "from 1 to 10000"),
    ("abco/maze3x3-pre-v0", "image_size=[50000,50000]", "image_size=50000 is out of range: from"
     " 6 to 4096"),
    ("abco/maze3x3-pre-v0", "image_size=2", "image_size=2 is out of range"),
    ("abco/maze3x3-pre-v0", "max_steps=1001", "max_steps=1001 is out of range"),
    ("abco/maze3x3-pre-v0", "episodes_per_layout=10000", "could hold 126 GiB of frames, more"
     " than the 32 GiB"),
    ("abco/maze3x3-expert-v0", "solutions_per_layout=0", "solutions_per_layout=0 is out of"),
    ("abco/maze3x3-pre-v0", "drop_wall_hits=1", "drop_wall_hits must be true or false"),
    ("abco/maze3x3-pre-v0", "seed=-1", "seed=-1 is out of range"),
    ("abco/acrobot-pre-held-v0", "hold=0", "hold=0 is out of range"),
    ("abco/acrobot-pre-held-v0", "hold=[5,2]", "hold[1]=2 is out of range: from 5"),
])
def test_each_bound_is_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], no_generation: None,
    dataset_id: str, override: str, message: str,
) -> None:
    out = tmp_path / "x.hdf5"
    assert cli.main(["generate", dataset_id, "--out", str(out), "--quiet",
                     "--set", override]) == cli.EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.startswith(f"error: {dataset_id}: ") and message in err and err.count("\n") == 1
    key, _, value = override.partition("=")
    with pytest.raises(InvalidParameterError, match="out of range|must be|could hold"):
        abco_data.generate(dataset_id, out, progress=False, **{key: eval(value)})
    assert list(tmp_path.iterdir()) == []


def test_bounds_leave_room_for_real_use() -> None:
    assert COUNT_BOUNDS["transitions"][1] >= 1_000_000
    spec = abco_data.spec("abco/maze10x10-procedural-expert-v0")
    assert spec.with_overrides(layouts=10_000).params["layouts"] == 10_000
    assert MAX_FRAME_BYTES > 10_000 * 100 * 64 * 64 * 3  # every 10x10 layout, longest paths


# --------------------------------------------------------------------------- command line


def test_broken_pipe_exits_quietly() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "abco_data", "list"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader goes away before a line is written (as `| head -0`)
    err = proc.stderr.read()
    assert proc.wait() == cli.EXIT_BROKEN_PIPE
    assert err == b""


def test_list_says_where_each_dataset_comes_from(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "published" not in lines[0] and "source" in lines[0]
    assert all(" generated " in line for line in lines[1:])  # the manifest pins no revision
    manifest = tmp_path / "manifest.json"
    manifest.write_text('{"revision": "' + "a" * 40 + '", "files": {"abco/maze3x3-pre-v0":'
                        ' {"filename": "maze3x3-pre-v0.hdf5", "size": 1, "sha256": "'
                        + "0" * 64 + '"}}}')
    monkeypatch.setenv("ABCO_DATA_MANIFEST", str(manifest))
    assert cli.main(["list"]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()[1:]}
    assert " Hub " in rows[PRE] and " generated " in rows["abco/maze3x3-expert-v0"]


def test_a_dataset_prints_as_one_short_line(tmp_path: Path) -> None:
    ds = abco_data.open_dataset(make_small(PRE, tmp_path))
    text = repr(ds)
    assert text == (f"Dataset(id='{PRE}', path='{ds.path}', kind='pre_demonstrations',"
                    f" episodes={ds.num_episodes}, transitions={ds.num_transitions})")
    assert str(ds) == text and "env_spec" not in text
    assert repr(ds.first_layouts(1)).endswith(", layouts_taken=1)")


def test_progress_in_a_log_is_a_few_whole_lines(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    abco_data.generate("abco/cartpole-pre-v0", tmp_path / "c.hdf5", progress=True,
                       transitions=3000, reference_episodes=1, reference_expert_episodes=1)
    err = capsys.readouterr().err  # captured: not a terminal
    lines = err.splitlines()
    assert "\r" not in err and 2 <= len(lines) <= 12
    assert lines[0].startswith("abco/cartpole-pre-v0:   0%")
    assert lines[-1].startswith("abco/cartpole-pre-v0: 100% 3000/3000 transitions")


def test_progress_on_a_terminal_is_tqdms_bar(monkeypatch: pytest.MonkeyPatch) -> None:
    from tqdm.auto import tqdm

    monkeypatch.setattr(progress, "is_terminal", lambda stream: True)
    bar = progress.progress_bar(total=3, disable=True)
    assert type(bar) is tqdm and not isinstance(bar, progress.LogProgress)
    monkeypatch.setattr(progress, "is_terminal", lambda stream: False)
    assert isinstance(progress.progress_bar(total=3, disable=True), progress.LogProgress)


def test_tests_never_touch_the_users_caches() -> None:
    import huggingface_hub.constants as constants

    home = Path.home() / ".cache"
    for folder in (abco_data.data_home(), Path(constants.HF_HUB_CACHE)):
        assert not folder.resolve().is_relative_to(home.resolve()), folder
    assert os.environ["ABCO_DATA_HOME"] != str(home / "abco" / "datasets")
