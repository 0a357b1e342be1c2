"""docs/format.md matches the files: read generated files with plain h5py, per the document."""

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from data_testing import make_small

import abco_data
from abco_data.format import (
    ACTION_COLUMNS,
    EPISODE_COLUMNS,
    FLAT_COLUMNS,
    MAZE_EPISODE_COLUMNS,
    PALETTE,
    POSITIONS,
    REFERENCE_COLUMNS,
    REQUIRED_ROOT_ATTRS,
    episode_column,
    space_from_json,
    space_to_json,
)

DOC = Path(__file__).resolve().parents[2] / "docs" / "format.md"


def _table(heading: str) -> list[list[str]]:
    """Body rows (cells) of the first table under the heading that starts with ``heading``."""
    lines = DOC.read_text().split(heading, 1)[1].splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("|"))
    table = []
    for line in lines[first:]:
        if not line.startswith("|"):
            break
        table.append([c.strip() for c in line.strip("|").split("|")])
    return table[2:]  # header and separator rows


def _decoded(path) -> np.ndarray:
    """The observations of ``path``, decoded by the document's plain-h5py snippet."""
    text = DOC.read_text().split("### Observation encoding", 1)[1]
    scope = {"h5py": h5py, "np": np, "path": path}
    exec(text.split("```python\n", 1)[1].split("```", 1)[0], scope)
    return scope["obs"]


def _name(cell: str) -> str:
    return re.search(r"`([^`]+)`", cell).group(1)


def test_documented_names_are_the_schemas():
    """The tables name exactly the columns of abco_data.format.schema."""
    flat = {_name(r[0]) for r in _table("### Flat columns")}
    assert flat == {*FLAT_COLUMNS, *ACTION_COLUMNS.values(), PALETTE, POSITIONS}
    per_episode = {_name(r[0]) for r in _table("### Per-episode columns")}
    assert per_episode == {episode_column(c) for c in EPISODE_COLUMNS + MAZE_EPISODE_COLUMNS}
    assert {_name(r[0]) for r in _table("### Reference returns")} == set(REFERENCE_COLUMNS)
    rows = {_name(r[0]): " ".join(r[2:]) for r in _table("### Flat columns")}
    for kind, column in ACTION_COLUMNS.items():
        assert f"`{kind}` only" in rows[column]


@pytest.fixture(scope="module", params=["abco/maze3x3-pre-v0", "abco/maze3x3-expert-v0",
                                        "abco/mountaincar-pre-v0"])
def path(request, tmp_path_factory):
    return make_small(request.param, tmp_path_factory.mktemp("doc"))


def test_root_attributes_as_documented(path):
    documented = [_name(r[0]) for r in _table("### Root attributes")]
    assert set(documented) >= set(REQUIRED_ROOT_ATTRS)
    with h5py.File(path) as f:
        assert set(f.attrs) == set(documented)
        assert f.attrs["format"] == "abco-dataset" and f.attrs["format_version"] == 1
        n_ep, n_tr = int(f.attrs["num_episodes"]), int(f.attrs["num_transitions"])
        assert f.attrs["num_observations"] == n_ep + n_tr
        for key in ("env_spec", "env_kwargs", "observation_space", "action_space",
                    "creation_params", "overrides"):
            json.loads(f.attrs[key])
        space = space_from_json(f.attrs["observation_space"])
        assert space_to_json(space) == f.attrs["observation_space"]


def test_columns_as_documented(path):
    with h5py.File(path) as f:
        kind = f.attrs["kind"]
        maze = f.attrs["env_id"].startswith("AbcoMaze")
        n_ep, n_tr = int(f.attrs["num_episodes"]), int(f.attrs["num_transitions"])
        sizes = {"(N + E,": n_tr + n_ep, "(N,)": n_tr, "(E,)": n_ep, "(E, n, n)": n_ep}
        tables = (_table("### Flat columns") + _table("### Per-episode columns"))
        for row in tables:
            name, shape, note = _name(row[0]), row[1], " ".join(row[2:])
            if shape.startswith("`(K, 3)`"):  # only with observation_encoding "palette"
                palette = f.attrs["observation_encoding"] != "raw"
                assert (name in f) == palette == maze, name
                if palette:
                    assert f[name].shape[1] == 3 and 1 <= len(f[name]) <= 256
                continue
            if "pre_demonstrations` only" in note and kind != "pre_demonstrations":
                assert name not in f
                continue
            if "`expert` only" in note and kind != "expert":
                assert name not in f
                continue
            if note.split("|")[-1].strip().startswith("mazes") or "mazes:" in note:
                assert (name in f) == maze, name
                if not maze:
                    continue
            assert name in f, name
            rows = next(v for k, v in sizes.items() if shape.strip("`").startswith(k))
            assert f[name].shape[0] == rows, name
        for row in _table("### Reference returns"):
            assert (_name(row[0]) in f) == maze


def test_transitions_per_the_document(path):
    """Rebuild every transition from the offsets alone and check the documented invariants."""
    obs = _decoded(path)
    with h5py.File(path) as f:
        off = f["episodes/obs_offset"][()]
        toff = f["episodes/transition_offset"][()]
        length = f["episodes/length"][()]
        term, trunc = f["terminations"][()], f["truncations"][()]
        rewards = f["rewards"][()]
        np.testing.assert_array_equal(off, toff + np.arange(len(off)))
        for e in range(len(off)):
            t = slice(toff[e], toff[e] + length[e])
            assert (term[t] | trunc[t])[-1] and not (term[t] | trunc[t])[:-1].any()
            assert rewards[t].sum() == pytest.approx(f["episodes/return"][e])
            s, s1 = obs[off[e] : off[e] + length[e]], obs[off[e] + 1 : off[e] + length[e] + 1]
            assert len(s) == len(s1) == length[e]
        if "positions" in f:
            from abco_envs.maze.render import MazeRenderer

            layout, pos = f["episodes/layout"][0], f["positions"][off[0]]
            frame = MazeRenderer(layout.shape[0], 64, 64).frame(layout, *pos)
            np.testing.assert_array_equal(frame, obs[off[0]])


def test_storage_as_documented(path):
    with h5py.File(path) as f:
        obs = f["observations"]
        image = f.attrs["env_id"].startswith("AbcoMaze")
        assert obs.compression == "gzip"
        assert obs.compression_opts == (3 if image else 6)
        if image:
            assert f.attrs["observation_encoding"] == "palette4"
            assert obs.shape[1:] == (64, 32) and obs.dtype == np.uint8 and obs.chunks[0] == 64
            palette = f["observation_palette"]
            assert palette.dtype == np.uint8 and palette.shape == (5, 3)
            assert palette.compression is None
            assert f["episodes/layout"].compression_opts == 3
        else:
            assert f.attrs["observation_encoding"] == "raw"
            assert "observation_palette" not in f
        assert f["rewards"].compression_opts == 6
        assert obs.maxshape[0] is None
        assert list(f.attrs) == sorted(f.attrs)


def test_decoding_snippet_of_the_document(path):
    """The document's plain-h5py snippet gives the frames abco's reader gives."""
    obs = _decoded(path)
    expected = abco_data.open_dataset(path).load_arrays().observations
    assert obs.dtype == expected.dtype
    np.testing.assert_array_equal(obs, expected)
