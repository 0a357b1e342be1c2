"""Maze frames kept as (layout, agent cell) and drawn when indexed: ``MazeFrames``, its torch
view ``frames_tensor``, and ``Dataset.load_arrays(observations=False)``."""

import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_data.format.arrays import MazeFrames
from abco_envs.maze.render import MazeRenderer

torch = pytest.importorskip("torch")
from abco_data.torch_view import DeviceFrameTensor, FrameTensor, frames_tensor  # noqa: E402


def _drawn(*datasets):
    """The datasets' frames drawn together (one background table) and their decoded columns."""
    arrays = [d.load_arrays(observations=False) for d in datasets]
    shape = datasets[0].observation_space.shape
    frames = MazeFrames.draw_columns(
        [(a.layouts, a.episode_lengths, a.positions) for a in arrays],
        height=shape[0], width=shape[1])
    return frames, [d.load_arrays().observations for d in datasets]


@pytest.fixture(scope="module")
def mazes(tmp_path_factory):
    """Small 5x5 procedural expert and pre files (4 layouts) and their first 3 layouts."""
    root = tmp_path_factory.mktemp("frames")
    paths = [make_small(f"abco/maze5x5-procedural-{k}-v0", root, layouts=4)
             for k in ("expert", "pre")]
    return [abco_data.open_dataset(p).first_layouts(3) for p in paths]


def test_drawn_frames_are_the_files_byte_for_byte(mazes, tmp_path):
    drawn, decoded_columns = _drawn(*mazes)
    for frames, decoded, view in zip(drawn, decoded_columns, mazes):
        assert frames.shape == decoded.shape and frames.dtype == decoded.dtype == np.uint8
        assert len(frames) == view.num_transitions + view.num_episodes
        assert np.asarray(frames).tobytes() == decoded.tobytes()
        assert frames.first_difference(lambda a, b, d=decoded: d[a:b]) is None
    expert, pre = drawn
    assert expert.backgrounds is pre.backgrounds and len(pre.backgrounds) == 3  # shared
    # a whole standard 3x3 file too (another grid, another frame size)
    ds = abco_data.open_dataset(make_small("abco/maze3x3-pre-v0", tmp_path))
    (frames,), (decoded,) = _drawn(ds)
    assert np.asarray(frames).tobytes() == decoded.tobytes()


def test_indexing_is_the_decoded_columns(mazes):
    (frames, _), (decoded, _) = _drawn(*mazes)
    rows = np.array([3, 0, len(decoded) - 1, 3, -2])
    for key in (rows, rows.tolist(), 5, -1, np.int64(7), np.array(2), slice(2, 9, 3),
                slice(None), decoded[:, 0, 0, 0] > 200):
        out = frames[key]
        assert out.dtype == np.uint8 and out.tobytes() == decoded[key].tobytes(), key
    assert frames[np.zeros(0, np.int64)].shape == (0, *decoded.shape[1:])
    np.testing.assert_array_equal(frames.astype(np.float64), decoded.astype(np.float64))
    with pytest.raises(IndexError):
        frames[len(decoded)]
    with pytest.raises(IndexError, match="indexed by integers, not float64"):
        frames[np.array([1.0])]
    with pytest.raises(TypeError, match="one index"):
        frames[1, 2]
    assert frames.nbytes < decoded.nbytes / 5


def test_frames_tensor_gives_the_tensors_of_the_decoded_column(mazes):
    (frames, _), (decoded, _) = _drawn(*mazes)
    view, old = frames_tensor(frames), torch.from_numpy(decoded)
    assert isinstance(view, FrameTensor) and len(view) == len(old)
    assert view.shape == old.shape and view.dtype == old.dtype
    rows = torch.tensor([4, 1, 1, len(old) - 2])
    for key in (rows, rows + 1, torch.tensor(3), rows.numpy(), 2):
        new = view[key]
        assert new.dtype == old[key].dtype and torch.equal(new, old[key])
    plain = frames_tensor(decoded)  # an array: its tensor, sharing its memory
    assert isinstance(plain, torch.Tensor) and plain.data_ptr() == decoded.ctypes.data


def test_device_frames_are_drawn_where_they_live_byte_for_byte(mazes):
    """The device view (here on the CPU, the one device every machine has) draws each row as
    the decoded column holds it, for every kind of row index a trainer passes."""
    (frames, _), (decoded, _) = _drawn(*mazes)
    view, old = DeviceFrameTensor(frames, torch.device("cpu")), torch.from_numpy(decoded)
    assert view.shape == old.shape and view.dtype == torch.uint8 and len(view) == len(old)
    rows = torch.tensor([4, 1, 1, len(old) - 2])
    for key in (rows, rows + 1, torch.tensor(3), rows.numpy(), 2, rows.reshape(2, 2)):
        assert torch.equal(view[key], old[key]), key
    assert view[torch.zeros(0, dtype=torch.long)].shape == (0, *old.shape[1:])
    changed = view[rows]
    changed[0] ^= 1  # a drawn batch is its own memory: the next draw is untouched
    assert torch.equal(view[rows], old[rows])
    # an accelerator's device gets the device view, the CPU keeps the numpy one
    assert isinstance(frames_tensor(frames, "cpu"), FrameTensor)
    assert isinstance(frames_tensor(frames, torch.device("meta")), DeviceFrameTensor)
    assert frames_tensor(decoded, "meta").device.type == "meta"


def test_first_difference_finds_the_first_changed_row(mazes):
    (frames, _), (decoded, _) = _drawn(*mazes)
    changed = decoded.copy()
    changed[7, 10, 10] ^= 1
    changed[len(changed) - 1, 0, 0] ^= 1
    assert frames.first_difference(lambda a, b: changed[a:b]) == 7
    assert frames.first_difference(lambda a, b: changed[a:b, :-1]) == 0  # another shape


def test_draw_columns_checks_its_columns():
    cells = np.full((2, 3, 3), 15, np.uint8)
    lengths, positions = np.array([1, 2]), np.zeros((5, 2), np.int64)
    with pytest.raises(ValueError, match="4 agent positions for 5 maze frames"):
        MazeFrames.draw_columns([(cells, lengths, positions[:4])], height=12, width=12)
    with pytest.raises(ValueError, match="one n x n size"):
        MazeFrames.draw_columns([(cells, lengths, positions),
                                 (np.full((1, 4, 4), 15, np.uint8), lengths[:1],
                                  positions[:2])], height=12, width=12)  # fmt: skip
    with pytest.raises(ValueError, match="too small"):
        MazeFrames.draw_columns([(cells, lengths, positions)], height=4, width=4)
    frames, = MazeFrames.draw_columns([(cells, lengths, positions)], height=12, width=12)
    assert len(frames.backgrounds) == 1  # the two episodes' layouts are one
    np.testing.assert_array_equal(frames[4], MazeRenderer(3, 12, 12).frame(cells[1], 0, 0))


def test_load_arrays_without_observations(mazes):
    pre = mazes[1]
    full, bare = pre.load_arrays(), pre.load_arrays(observations=False)
    assert bare.observations.shape == (0, *full.observations.shape[1:])
    for name, value in vars(full).items():
        if name != "observations" and isinstance(value, np.ndarray):
            np.testing.assert_array_equal(getattr(bare, name), value)
