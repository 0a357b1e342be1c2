"""Bad input: each gets a clear error naming the file, and nothing is half-written."""

import errno
import os

import h5py
import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_data.errors import (
    ChecksumError,
    CorruptDatasetError,
    DatasetWriteError,
    FormatVersionError,
    UnknownDatasetError,
    WrongKindError,
)
from abco_data.format import writer


@pytest.fixture()
def good(tmp_path):
    return make_small("abco/maze3x3-pre-v0", tmp_path)


def test_truncated_file(good):
    data = good.read_bytes()
    good.write_bytes(data[: len(data) // 2])
    with pytest.raises(CorruptDatasetError, match="truncated") as err:
        abco_data.open_dataset(good)
    assert str(good) in str(err.value)


def test_not_hdf5(tmp_path):
    path = tmp_path / "junk.hdf5"
    path.write_bytes(os.urandom(4096))
    with pytest.raises(CorruptDatasetError, match="junk.hdf5"):
        abco_data.open_dataset(path)


def test_plain_hdf5_is_not_a_dataset(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(CorruptDatasetError, match="not an abco dataset"):
        abco_data.open_dataset(path)


def test_corrupt_chunk_is_found_by_verify(good):
    with h5py.File(good) as f:
        info = f["observations"].id.get_chunk_info(0)
    with open(good, "r+b") as fh:
        fh.seek(info.byte_offset + 10)
        fh.write(b"\xff" * 64)
    with pytest.raises(ChecksumError, match="the bytes abco generates") as err:
        abco_data.verify(good)
    assert str(good) in str(err.value)
    # Given the new bytes as the expected ones, reading them still fails.
    with pytest.raises(CorruptDatasetError, match="observations") as err:
        abco_data.verify(good, sha256=abco_data.sha256_of(good))
    assert str(good) in str(err.value)


def test_wrong_format_version(good):
    with h5py.File(good, "a") as f:
        f.attrs["format_version"] = 99
    with pytest.raises(FormatVersionError, match="format_version 99") as err:
        abco_data.open_dataset(good)
    assert str(good) in str(err.value)


def test_wrong_kind_or_id(good):
    with pytest.raises(WrongKindError, match="not expert"):
        abco_data.open_dataset(good, kind="expert")
    with pytest.raises(WrongKindError, match="abco/maze5x5-pre-v0"):
        abco_data.open_dataset(good, dataset_id="abco/maze5x5-pre-v0")
    assert abco_data.open_dataset(good, kind="pre_demonstrations").kind == "pre_demonstrations"


def test_missing_column(good):
    with h5py.File(good, "a") as f:
        del f["rewards"]
    with pytest.raises(CorruptDatasetError, match="missing column.*rewards"):
        abco_data.open_dataset(good)


def test_inconsistent_offsets(good):
    with h5py.File(good, "a") as f:
        f["episodes/length"][0] += 1
    with pytest.raises(CorruptDatasetError, match="inconsistent"):
        abco_data.open_dataset(good)


def test_checksum_mismatch(good):
    with pytest.raises(ChecksumError, match="sha256") as err:
        abco_data.verify(good, sha256="0" * 64)
    assert str(good) in str(err.value)
    with pytest.raises(ChecksumError, match="size"):
        abco_data.verify(good, size=1)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.hdf5"):
        abco_data.open_dataset(tmp_path / "nothere.hdf5")


def test_unknown_id(tmp_path):
    with pytest.raises(UnknownDatasetError, match="known ids"):
        abco_data.generate("abco/nope-v0", tmp_path / "x.hdf5")


def test_full_disk_leaves_target_untouched(tmp_path, monkeypatch):
    target = make_small("abco/maze3x3-pre-v0", tmp_path)
    before = target.read_bytes()
    calls = {"n": 0}
    real_flush = writer._Column.flush

    def flush(self, final):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_flush(self, final)

    monkeypatch.setattr(writer._Column, "flush", flush)
    with pytest.raises(DatasetWriteError, match="no space left") as err:
        make_small("abco/maze3x3-pre-v0", tmp_path, layouts=1)
    assert err.value.errno == errno.ENOSPC and str(target) in str(err.value)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_interrupted_generation_leaves_nothing(tmp_path, monkeypatch):
    def boom(self, final):
        raise KeyboardInterrupt

    monkeypatch.setattr(writer._Column, "flush", boom)
    with pytest.raises(KeyboardInterrupt):
        make_small("abco/maze3x3-expert-v0", tmp_path)
    assert list(tmp_path.iterdir()) == []
