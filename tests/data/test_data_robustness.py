"""Nothing crashes, hangs or trusts bad data: fuzzing, a full disk, damaged heaps, checks."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_data import cli
from abco_data.errors import (
    ChecksumError,
    CorruptDatasetError,
    DatasetWriteError,
    FormatVersionError,
    WrongKindError,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture()
def small(tmp_path: Path) -> Path:
    return make_small("abco/maze3x3-pre-v0", tmp_path)


# -- fuzzing ---------------------------------------------------------------------------------


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the fuzz runs each case in a fork")
def test_fuzzed_files_end_in_our_error_or_the_original_data() -> None:
    """100 seeded corruptions through open, load_arrays, episodes, the torch view and verify.

    ``python tests/data/fuzzing.py --cases 1000`` runs more, and check_dataset and the
    command line too.
    """
    import fuzzing

    bad: list[str] = []
    results = fuzzing.run(100, seed=8, timeout=60.0, log=bad.append,
                          readers=("open", "load_arrays", "episodes", "torch", "verify"),
                          layouts=1, episodes_per_layout=3)
    assert sum(results.values()) >= 400
    assert bad == []


# -- a full or read-only disk ----------------------------------------------------------------


def _tmpfs(path: Path, size: str, *options: str) -> None:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("needs root to mount a small tmpfs")
    path.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", ",".join([f"size={size}", *options]),
                           "tmpfs", str(path)], capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")


@pytest.fixture()
def tiny_disk(tmp_path: Path):
    disk = tmp_path / "disk"
    _tmpfs(disk, "160k")
    yield disk
    subprocess.run(["umount", str(disk)], check=False)


@pytest.fixture()
def read_only_disk(tmp_path: Path):
    disk = tmp_path / "ro"
    _tmpfs(disk, "1m", "ro")
    yield disk
    subprocess.run(["umount", str(disk)], check=False)


_WRITER = textwrap.dedent("""
    import gc, os, sys
    import abco_data
    from abco_data.errors import DatasetWriteError
    target = sys.argv[1]
    for attempt in ("generate", "load"):
        try:
            if attempt == "generate":
                abco_data.generate("abco/maze3x3-pre-v0", os.path.join(target, "x.hdf5"),
                                   progress=False)
            else:
                os.environ["ABCO_DATA_HOME"] = os.path.join(target, "cache")
                abco_data.load("abco/maze3x3-pre-v0", offline=True, progress=False)
            print(attempt, "wrote")
        except DatasetWriteError as err:
            print(attempt, "error:", err)
        gc.collect()  # nothing half-closed is left for the garbage collector
    print("alive")
""")


def _run_writer(target: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO), "HF_HUB_OFFLINE": "1"}
    return subprocess.run([sys.executable, "-c", _WRITER, str(target)], capture_output=True,
                          text=True, timeout=300, env=env, cwd=REPO)


def test_full_disk_is_a_clear_error_not_a_crash(tiny_disk: Path) -> None:
    done = _run_writer(tiny_disk)
    assert done.returncode == 0, f"exit {done.returncode} (-11: segfault): {done.stderr}"
    lines = done.stdout.splitlines()
    assert lines[-1] == "alive"
    assert lines[0].startswith("generate error: ") and "no space left on device" in lines[0]
    assert str(tiny_disk / "x.hdf5") in lines[0]
    assert lines[1].startswith("load error: ") and "no space left on device" in lines[1]
    assert "Traceback" not in done.stderr
    assert [p.name for p in tiny_disk.rglob("*") if p.is_file()] == []  # no temporaries


def test_read_only_disk_is_a_clear_error(read_only_disk: Path) -> None:
    done = _run_writer(read_only_disk)
    assert done.returncode == 0, done.stderr
    assert "generate error: " in done.stdout and "Read-only file system" in done.stdout
    assert "load error: " in done.stdout and str(read_only_disk / "cache") in done.stdout


def test_cache_that_is_a_file_is_a_clear_error(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    home = tmp_path / "home"
    home.write_text("not a folder")
    monkeypatch.setenv("ABCO_DATA_HOME", str(home))
    with pytest.raises(DatasetWriteError, match="cannot write .* into the dataset cache") as err:
        abco_data.load("abco/maze3x3-pre-v0", offline=True, progress=False)
    assert str(home) in str(err.value) and "ABCO_DATA_HOME" in str(err.value)
    assert home.read_text() == "not a folder"


# -- damaged files ---------------------------------------------------------------------------


def _zero_heap_object(path: Path) -> None:
    """Zero the header of the first object of the file's first global heap: HDF5 reads it as
    free space of size 0 and loops forever on it."""
    data = bytearray(path.read_bytes())
    at = data.find(b"GCOL") + 16
    data[at : at + 16] = bytes(16)
    path.write_bytes(bytes(data))


def test_a_zeroed_heap_block_ends_in_an_error_not_a_hang(small: Path) -> None:
    _zero_heap_object(small)
    code = ("import sys; from abco_data import cli;"
            f" sys.exit(cli.main(['verify', {str(small)!r}]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 1
    assert done.stderr.startswith(f"error: {small}: global heap collection at byte")
    with pytest.raises(CorruptDatasetError, match="global heap"):
        abco_data.open_dataset(small)


def test_torch_view_names_the_file_of_a_damaged_chunk(small: Path) -> None:
    torch = pytest.importorskip("torch")
    with h5py.File(small) as f:
        info = f["observations"].id.get_chunk_info(0)
    with open(small, "r+b") as fh:
        fh.seek(info.byte_offset + 10)
        fh.write(b"\xff" * 64)
    # Opened after the damage (a file changed after opening is refused as changed, not read).
    view = abco_data.open_dataset(small).torch_dataset()
    loader = torch.utils.data.DataLoader(view, batch_size=8)
    with pytest.raises(CorruptDatasetError, match="observations cannot be read") as err:
        list(loader)
    assert str(small) in str(err.value)
    ds = abco_data.open_dataset(small)
    with pytest.raises(CorruptDatasetError, match="observations"):
        list(ds.episodes())


# -- verify and check_dataset ----------------------------------------------------------------


def _set_attr(path: Path, name: str, value: object) -> None:
    with h5py.File(path, "a") as f:
        f.attrs[name] = value


def test_verify_checks_the_bytes_whatever_the_file_says(small: Path) -> None:
    report = abco_data.verify(small)
    assert report.checksum.startswith("the bytes abco generates for abco/maze3x3-pre-v0 with")
    _set_attr(small, "overrides", "[]")  # claims to be the published file: it is not
    with pytest.raises(ChecksumError, match="manifest entry of abco/maze3x3-pre-v0"):
        abco_data.verify(small)
    _set_attr(small, "overrides", json.dumps(["layouts"]))  # another variant: not that either
    with pytest.raises(ChecksumError, match="generates for abco/maze3x3-pre-v0 with layouts"):
        abco_data.verify(small)


def test_non_finite_values_are_rejected(small: Path) -> None:
    with h5py.File(small, "a") as f:
        f["rewards"][0] = np.nan
    with pytest.raises(ChecksumError):
        abco_data.verify(small)
    with pytest.raises(CorruptDatasetError, match="rewards hold NaN or infinite"):
        abco_data.verify(small, sha256=abco_data.sha256_of(small))  # bytes "as expected"
    with pytest.raises(CorruptDatasetError, match="NaN"):
        abco_data.open_dataset(small).load_arrays()


def test_a_group_in_place_of_a_column_is_corrupt(small: Path) -> None:
    with h5py.File(small, "a") as f:
        del f["rewards"]
        f.create_group("rewards")
    with pytest.raises(CorruptDatasetError, match="rewards is an HDF5 Group, not a column"):
        abco_data.open_dataset(small)


def test_moves_that_break_the_walls_are_rejected(small: Path) -> None:
    ds = abco_data.open_dataset(small)
    a = ds.load_arrays()
    ds.close()
    with h5py.File(small, "a") as f:
        f["actions"][0] = (a.actions[0] + 1) % 4  # same frames, another action
    with pytest.raises(CorruptDatasetError, match="transition 0 moves the agent"):
        abco_data.verify(small, sha256=abco_data.sha256_of(small))


def test_check_dataset_checks_kind_env_and_version(small: Path) -> None:
    ds = abco_data.check_dataset(small, kind="pre_demonstrations", env_id="AbcoMaze3x3-v0")
    assert ds.id == "abco/maze3x3-pre-v0"
    assert abco_data.check_dataset(ds) is ds
    ds.close()
    with pytest.raises(WrongKindError, match="not expert"):
        abco_data.check_dataset(small, kind="expert")
    with pytest.raises(WrongKindError, match="not CartPole-v1"):
        abco_data.check_dataset(small, env_id="CartPole-v1")
    _set_attr(small, "format_version", 2)
    with pytest.raises(FormatVersionError):
        abco_data.check_dataset(small)


def test_verify_takes_an_id(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                            capsys: pytest.CaptureFixture) -> None:
    home = tmp_path / "cache"
    path = make_small("abco/cartpole-expert-v0", home)
    data = path.read_bytes()
    manifest = tmp_path / "manifest.json"
    manifest.write_text(json.dumps({"revision": None, "files": {"abco/cartpole-expert-v0": {
        "filename": path.name, "size": len(data), "sha256": abco_data.sha256_of(path)}}}))
    monkeypatch.setenv("ABCO_DATA_HOME", str(home))
    monkeypatch.setenv("ABCO_DATA_MANIFEST", str(manifest))
    assert cli.main(["verify", "abco/cartpole-expert-v0"]) == 0
    assert capsys.readouterr().out.startswith(f"OK {path}: abco/cartpole-expert-v0")
    path.unlink()
    assert cli.main(["verify", "abco/cartpole-expert-v0"]) == 2
    assert "no such dataset file" in capsys.readouterr().err
    assert cli.main(["verify", "abco/nope-v0"]) == 2
