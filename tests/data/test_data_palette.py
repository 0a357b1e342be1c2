"""Palette encoding of image observations: lossless, deterministic, transparent to readers."""

import hashlib

import h5py
import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_data.errors import ChecksumError, CorruptDatasetError
from abco_data.format import IMAGE_CHUNK_ROWS, DatasetWriter, ObservationReader
from abco_data.format.palette import PaletteDecoder, PaletteEncoder, pack4, unpack4


def _frames(n, h=6, w=5, colours=5, seed=0):
    rng = np.random.default_rng(seed)
    palette = rng.integers(256, size=(colours, 3), dtype=np.uint8)
    return palette[rng.integers(colours, size=(n, h, w))]


def _write(path, frames, pieces):
    with DatasetWriter(path) as w:
        for part in np.array_split(frames, pieces):
            w.append("observations", part)
    return path


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_pack4_round_trip():
    idx = np.random.default_rng(0).integers(16, size=(3, 4, 10), dtype=np.uint8)
    assert pack4(idx).shape == (3, 4, 5)
    np.testing.assert_array_equal(unpack4(pack4(idx)), idx)


@pytest.mark.parametrize("shape", [(1, 1, 1), (3, 5, 7), (2, 64, 64), (9, 3, 3), (1, 2, 6)])
def test_decoder_matches_palette_indexing(shape):
    rng = np.random.default_rng(1)
    palette = rng.integers(256, size=(200, 3), dtype=np.uint8)
    idx = rng.integers(200, size=shape, dtype=np.uint8)
    for packed in (False, True):
        if packed:
            idx = idx[..., : idx.shape[-1] // 2 * 2] % 16
            if not idx.size:
                continue
        data = pack4(idx) if packed else idx
        for fast in (None, False):
            dec = PaletteDecoder(palette, packed=packed, _fast=fast)
            np.testing.assert_array_equal(dec.decode(data), palette[idx])
            dec.BLOCK_PIXELS = 12  # many blocks, odd and even sizes
            np.testing.assert_array_equal(dec.decode(data), palette[idx])
            out = np.zeros((*idx.shape[:-1], 2 * idx.shape[-1], 3), np.uint8)[..., ::2, :]
            dec.decode_into(data, out)  # a strided output
            np.testing.assert_array_equal(out, palette[idx])


@pytest.mark.parametrize("packed", [False, True])
def test_decoder_matches_palette_indexing_on_every_byte_pair(packed):
    """Every table entry (all 65,536 pairs of stored bytes, odd length), also past the palette."""
    rng = np.random.default_rng(7)
    palette = rng.integers(256, size=(16 if packed else 256, 3), dtype=np.uint8)
    pairs = rng.permutation(1 << 16).astype("<u2").view(np.uint8)
    data = np.concatenate([pairs, rng.integers(256, size=5, dtype=np.uint8)])
    idx = unpack4(data) if packed else data
    for fast in (None, False):
        dec = PaletteDecoder(palette, packed=packed, _fast=fast)
        np.testing.assert_array_equal(dec.decode(data), palette[idx])
        short = PaletteDecoder(palette[:3], packed=packed, _fast=fast).decode(data)
        black = np.zeros(3, np.uint8)  # indices past the palette (a corrupt file)
        np.testing.assert_array_equal(short, np.where((idx < 3)[..., None],
                                                      palette[np.minimum(idx, 2)], black))


def test_encoder_first_appearance_order():
    frames = np.zeros((2, 2, 2, 3), np.uint8)
    frames[0, 0, 1] = (9, 9, 9)
    frames[0, 1, 0] = (1, 2, 3)
    frames[1, 1, 1] = (255, 0, 7)
    enc = PaletteEncoder()
    idx = enc.encode(frames[:1])
    idx2 = enc.encode(frames[1:])
    assert enc.palette.tolist() == [[0, 0, 0], [9, 9, 9], [1, 2, 3], [255, 0, 7]]
    np.testing.assert_array_equal(enc.palette[np.concatenate([idx, idx2])], frames)


def test_file_is_palette_and_lossless(tmp_path):
    frames = _frames(3 * IMAGE_CHUNK_ROWS + 5)
    path = _write(tmp_path / "a.hdf5", frames, 7)
    with h5py.File(path) as f:
        assert f.attrs["observation_encoding"] == "palette"  # odd width: one index a byte
        assert f["observations"].shape == frames.shape[:-1]
        assert f["observations"].dtype == np.uint8
        palette = f["observation_palette"][()]
        np.testing.assert_array_equal(palette[f["observations"][()]], frames)  # plain h5py
        reader = ObservationReader(f)
        reader.BLOCK_CHUNKS = 1  # several blocks, the last one short
        np.testing.assert_array_equal(reader.read(), frames)
        np.testing.assert_array_equal(reader.read(3, 150), frames[3:150])
        np.testing.assert_array_equal(reader[10:12], frames[10:12])
        rows = np.array([150, 2, 2, 70, 0])
        np.testing.assert_array_equal(reader.rows(rows), frames[rows])


def test_bytes_independent_of_append_pattern(tmp_path):
    frames = _frames(5 * IMAGE_CHUNK_ROWS + 3, colours=40)
    a = _write(tmp_path / "a.hdf5", frames, 1)
    b = _write(tmp_path / "b.hdf5", frames, 37)
    assert _sha(a) == _sha(b)


@pytest.mark.parametrize("colours, width, encoding", [
    (16, 18, "palette4"), (16, 17, "palette"), (17, 18, "palette"), (256, 18, "palette"),
    (257, 18, "raw")])
def test_encoding_by_colours(tmp_path, colours, width, encoding):
    code = np.arange(colours) * 977 + 5  # distinct colours
    palette = np.stack([code & 255, (code >> 8) & 255, code >> 16], 1).astype(np.uint8)
    idx = np.random.default_rng(2).integers(colours, size=(70, 16, width))
    idx[0].reshape(-1)[:colours] = np.arange(colours)  # every colour appears
    frames = palette[idx]
    path = _write(tmp_path / "x.hdf5", frames, 3)
    with h5py.File(path) as f:
        assert f.attrs["observation_encoding"] == encoding
        assert ("observation_palette" in f) == (encoding != "raw")
        if encoding == "palette4":
            assert f["observations"].shape == (70, 16, width // 2)
        reader = ObservationReader(f)
        assert reader.shape == frames.shape
        np.testing.assert_array_equal(reader.read(), frames)
        np.testing.assert_array_equal(reader.rows(np.array([69, 0, 5])), frames[[69, 0, 5]])


@pytest.mark.parametrize("more, encoding", [(30, "palette"), (None, "raw")])
def test_growth_after_written_chunks_rewrites(tmp_path, more, encoding):
    few = _frames(9 * IMAGE_CHUNK_ROWS, w=6, colours=3)  # flushed as palette4 chunks first
    rng = np.random.default_rng(3)
    if more is None:
        many = rng.integers(256, size=(12, 6, 6, 3), dtype=np.uint8)  # > 256 colours
    else:
        many = _frames(4, w=6, colours=more, seed=4)
    frames = np.concatenate([few, many])
    path = _write(tmp_path / "x.hdf5", frames, 12)
    with h5py.File(path) as f:
        assert f.attrs["observation_encoding"] == encoding
        assert ("observation_palette" in f) == (encoding != "raw")
        np.testing.assert_array_equal(ObservationReader(f).read(), frames)
    again = _write(tmp_path / "y.hdf5", frames, 3)
    assert _sha(path) == _sha(again)


def test_vector_observations_stay_raw(tmp_path):
    with DatasetWriter(tmp_path / "v.hdf5") as w:
        w.append("observations", np.ones((5, 4), np.float32))
    with h5py.File(tmp_path / "v.hdf5") as f:
        assert f.attrs["observation_encoding"] == "raw"


@pytest.fixture
def maze(tmp_path):
    return make_small("abco/maze3x3-pre-v0", tmp_path)


def test_palette_index_out_of_range_is_found_by_every_reader(maze):
    with h5py.File(maze, "a") as f:
        assert f.attrs["observation_encoding"] == "palette4"
        f["observations"][0, 0, 0] = 0x9C  # nibbles 12 and 9
    with pytest.raises(ChecksumError):  # the bytes are not the generator's
        abco_data.verify(maze)
    ds = abco_data.open_dataset(maze)
    for read in (ds.load_arrays, lambda: ds.episode(0), lambda: ds.torch_dataset()[0],
                 lambda: abco_data.verify(maze, sha256=abco_data.sha256_of(maze))):
        with pytest.raises(CorruptDatasetError, match="palette indices beyond the 5") as err:
            read()
        assert str(maze) in str(err.value)


def test_missing_palette_is_reported(maze):
    with h5py.File(maze, "a") as f:
        del f["observation_palette"]
    with pytest.raises(CorruptDatasetError, match="observation_palette") as err:
        abco_data.open_dataset(maze)
    assert str(maze) in str(err.value)


def test_unknown_encoding_is_reported(maze):
    with h5py.File(maze, "a") as f:
        f.attrs["observation_encoding"] = "jpeg"
    with pytest.raises(CorruptDatasetError, match="unknown observation_encoding 'jpeg'"):
        abco_data.open_dataset(maze)


def test_every_reader_decodes(maze):
    ds = abco_data.open_dataset(maze)
    with h5py.File(maze) as f:
        frames = f["observation_palette"][()][unpack4(f["observations"][()])]
    a = ds.load_arrays()
    np.testing.assert_array_equal(a.observations, frames)
    ep = ds.episode(1)
    o = int(a.episode_starts[1])
    np.testing.assert_array_equal(ep.observations, frames[o : o + ep.length + 1])
    s, _, s1 = ds.read_transitions([3, 0])
    obs_t, _ = ds.transition_index()
    np.testing.assert_array_equal(s, frames[obs_t[[3, 0]]])
    np.testing.assert_array_equal(s1, frames[obs_t[[3, 0]] + 1])
    assert len(ds.observation_palette) == 5
    for in_memory in (False, True):
        view = ds.torch_dataset(in_memory=in_memory)
        first, _, last = view[3]
        np.testing.assert_array_equal(first.numpy(), frames[obs_t[3]])
        np.testing.assert_array_equal(last.numpy(), frames[obs_t[3] + 1])
    ds.close()


def test_maze_frames_decode_like_plain_h5py(tmp_path):
    """Every read path of a generated maze file gives the plain ``palette[indices]`` frames."""
    path = make_small("abco/maze3x3-pre-v0", tmp_path, episodes_per_layout=20, max_steps=10)
    with h5py.File(path) as f:
        assert f.attrs["observation_encoding"] == "palette4"
        plain = f["observation_palette"][()][unpack4(f["observations"][()])]
        n = len(plain)
        assert n > 3 * IMAGE_CHUNK_ROWS and n % IMAGE_CHUNK_ROWS  # a short last chunk
        reader = ObservationReader(f)
        assert reader._raw_chunks  # whole chunks are inflated by the reader itself
        np.testing.assert_array_equal(reader.read(), plain)
        for start, stop in [(0, 64), (3, 200), (64, n), (70, 75), (n - 1, n), (5, 5)]:
            np.testing.assert_array_equal(reader.read(start, stop), plain[start:stop])
        rows = np.array([n - 1, 0, 0, 130, 64])
        np.testing.assert_array_equal(reader.rows(rows), plain[rows])
    ds = abco_data.open_dataset(path)
    np.testing.assert_array_equal(ds.load_arrays().observations, plain)
    np.testing.assert_array_equal(np.concatenate([e.observations for e in ds.episodes()]),
                                  plain)
    ds.close()


def test_reader_leaves_unusual_chunks_to_hdf5(tmp_path):
    rng = np.random.default_rng(5)
    palette = rng.integers(256, size=(16, 3), dtype=np.uint8)
    stored = rng.integers(256, size=(10, 3, 4), dtype=np.uint8)  # packed; chunks of 4 rows
    with h5py.File(tmp_path / "a.h5", "w") as f:
        f.attrs["observation_encoding"] = "palette4"
        f["observation_palette"] = palette
        ds = f.create_dataset("observations", data=stored, chunks=(4, 3, 4),
                              compression="gzip", maxshape=(None, 3, 4))
        ds.id.write_direct_chunk((4, 0, 0), stored[4:8].tobytes(), filter_mask=1)  # skipped
        ds.resize(14, axis=0)  # chunk 3 never written: HDF5's fill value, zeros
    expect = palette[unpack4(np.concatenate([stored, np.zeros((4, 3, 4), np.uint8)]))]
    with h5py.File(tmp_path / "a.h5") as f:
        reader = ObservationReader(f)
        assert reader._raw_chunks
        np.testing.assert_array_equal(reader.read(), expect)
        np.testing.assert_array_equal(reader.read(2, 13), expect[2:13])
    with h5py.File(tmp_path / "a.h5", "a") as f:
        f["observations"].id.write_direct_chunk((8, 0, 0), b"not deflate data")
    with h5py.File(tmp_path / "a.h5") as f, pytest.raises(CorruptDatasetError) as err:
        ObservationReader(f).read()  # HDF5's own error, named by the reader
    assert isinstance(err.value.__cause__, OSError)
    with h5py.File(tmp_path / "b.h5", "w") as f:
        f.attrs["observation_encoding"] = "palette4"
        f["observation_palette"] = palette
        f.create_dataset("observations", data=stored, chunks=(4, 3, 4), compression="gzip",
                         shuffle=True)
    with h5py.File(tmp_path / "b.h5") as f:
        reader = ObservationReader(f)
        assert not reader._raw_chunks  # another filter pipeline: all through HDF5
        np.testing.assert_array_equal(reader.read(), expect[:10])
