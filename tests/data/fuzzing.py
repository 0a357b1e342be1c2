"""Corrupt a small dataset file in many ways and see that abco_data never trusts the result.

Five families of corruption, drawn from one seed: byte flips, truncations, zeroed blocks,
edits made with h5py of attributes, of structure and of values out of their range ("edit"),
and edits of values within their range ("plausible": another action, another palette colour).
Each corrupted file goes through every way of reading it (``open_dataset``, ``load_arrays``,
``episodes``, the file-backed torch dataset, ``check_dataset``, ``verify`` and ``abco data
verify``) in a forked child with a time limit, so a segfault or a hang is seen as such. Every
way must end in abco_data's own error or give data identical to the original, except that a
plausible edit is the checkers' business only (``check_dataset`` and ``verify`` find it by
the checksum; the plain readers cannot know the values were not those generated).

Outcomes of one reading: ``ok-error`` (a :class:`~abco_data.errors.DatasetError`),
``ok-same`` (data identical to the original), ``raw:<type>`` (another exception),
``accepted`` (different data, no error), ``hang`` and ``crash:<signal>``.

Run ``python tests/data/fuzzing.py --cases 1000`` for a larger count than the test suite's.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

# Run as a script: this checkout's abco_data and the test helpers beside this file.
sys.path[:0] = [str(Path(__file__).resolve().parents[2]), str(Path(__file__).resolve().parent)]
from data_testing import make_small  # noqa: E402

import abco_data  # noqa: E402
from abco_data.errors import DatasetError  # noqa: E402
from abco_data.user.forked_call import run_in_child  # noqa: E402

FAMILIES = ("flip", "truncate", "zero", "edit", "plausible")
READERS = ("open", "load_arrays", "episodes", "torch", "check", "verify", "cli_verify")
#: The readers that must find plausible edits.
CHECKERS = ("check", "verify", "cli_verify")
GOOD = ("ok-error", "ok-same")


@dataclass(frozen=True)
class Case:
    """One corruption: its family, a description, and how to make it from the original."""

    family: str
    what: str
    apply: Callable[[Path], None]


def _edit_attr(name: str, value: object) -> Callable[[Path], None]:
    def apply(path: Path) -> None:
        with h5py.File(path, "a") as f:
            f.attrs[name] = value
    return apply


def _edit_values(column: str, index: int, value: object) -> Callable[[Path], None]:
    def apply(path: Path) -> None:
        with h5py.File(path, "a") as f:
            f[column][index] = value
    return apply


def _delete(name: str) -> Callable[[Path], None]:
    def apply(path: Path) -> None:
        with h5py.File(path, "a") as f:
            del f[name]
    return apply


#: Edits a careless tool or a malicious file could make, each a valid HDF5 file.
EDITS: tuple[tuple[str, Callable[[Path], None]], ...] = (
    ("format_version=2", _edit_attr("format_version", 2)),
    ("format_version='1'", _edit_attr("format_version", "1")),
    ("kind=expert", _edit_attr("kind", "expert")),
    ("kind=robot", _edit_attr("kind", "robot")),
    ("num_episodes+1", lambda p: _edit_attr("num_episodes", _attr(p, "num_episodes") + 1)(p)),
    ("num_transitions=-1", _edit_attr("num_transitions", -1)),
    ("num_episodes=str", _edit_attr("num_episodes", "many")),
    ("observation_space=junk", _edit_attr("observation_space", "{not json")),
    ("observation_space=other", _edit_attr("observation_space", json.dumps(
        {"type": "Box", "shape": [2], "dtype": "float32", "low": 0, "high": 1}))),
    ("action_space=Discrete(2)", _edit_attr("action_space", json.dumps(
        {"type": "Discrete", "n": 2, "start": 0}))),
    ("action_space=[]", _edit_attr("action_space", "[]")),
    ("observation_encoding=raw", _edit_attr("observation_encoding", "raw")),
    ("observation_encoding=palette", _edit_attr("observation_encoding", "palette")),
    ("observation_encoding=png", _edit_attr("observation_encoding", "png")),
    ("overrides=[]", _edit_attr("overrides", "[]")),
    ("overrides=junk", _edit_attr("overrides", "{")),
    ("dataset_id=other", _edit_attr("dataset_id", "abco/maze5x5-pre-v0")),
    ("dataset_id=unknown", _edit_attr("dataset_id", "someone/else-v0")),
    ("env_id=CartPole", _edit_attr("env_id", "CartPole-v1")),
    ("reference_expert_mean=nan", _edit_attr("reference_expert_mean", float("nan"))),
    ("reference_random_mean=str", _edit_attr("reference_random_mean", "low")),
    ("creation_params=junk", _edit_attr("creation_params", "]")),
    ("rewards[0]=nan", _edit_values("rewards", 0, np.nan)),
    ("rewards[1]=inf", _edit_values("rewards", 1, np.inf)),
    ("return[0]=-inf", _edit_values("episodes/return", 0, -np.inf)),
    ("length[0]+=1", lambda p: _edit_values("episodes/length", 0, _value(p, "episodes/length", 0)
                                            + 1)(p)),
    ("length[0]=0", _edit_values("episodes/length", 0, 0)),
    ("obs_offset[1]=0", _edit_values("episodes/obs_offset", 1, 0)),
    ("transition_offset[2]=-5", _edit_values("episodes/transition_offset", 2, -5)),
    ("positions[3]=(9,9)", _edit_values("positions", 3, (9, 9))),
    ("positions[4]=(-1,0)", _edit_values("positions", 4, (-1, 0))),
    ("layout[0]=255", _edit_values("episodes/layout", 0, np.full((3, 3), 255, np.uint8))),
    ("layout_index[0]=-1", _edit_values("episodes/layout_index", 0, -1)),
    ("actions[0]=7", _edit_values("actions", 0, 7)),
    ("actions[0]=-1", _edit_values("actions", 0, -1)),
    ("terminations[0]=1", _edit_values("terminations", 0, True)),
    ("truncations[-1]=0", _edit_values("truncations", -1, False)),
    ("observations[0]=255", _edit_values("observations", 0, 255)),
    ("del rewards", _delete("rewards")),
    ("del observation_palette", _delete("observation_palette")),
    ("del episodes/layout", _delete("episodes/layout")),
    ("del reference/layout_ids", _delete("reference/layout_ids")),
)


#: Edits of values within their range: only a checksum tells them from generated data.
PLAUSIBLE_EDITS: tuple[tuple[str, Callable[[Path], None]], ...] = (
    ("palette[0]=(1,2,3)", _edit_values("observation_palette", 0, (1, 2, 3))),
    ("actions[0]+=1", lambda p: _edit_values("actions", 0,
                                             (_value(p, "actions", 0) + 1) % 4)(p)),
    ("seed[0]+=1", lambda p: _edit_values("episodes/seed", 0,
                                          _value(p, "episodes/seed", 0) + 1)(p)),
    ("observations[1]=observations[0]", lambda p: _copy_row(p, "observations", 0, 1)),
)


def _copy_row(path: Path, column: str, source: int, target: int) -> None:
    with h5py.File(path, "a") as f:
        f[column][target] = f[column][source]


def _attr(path: Path, name: str) -> int:
    with h5py.File(path) as f:
        return int(f.attrs[name])


def _value(path: Path, column: str, index: int) -> int:
    with h5py.File(path) as f:
        return int(f[column][index])


def _write_bytes(data: bytes) -> Callable[[Path], None]:
    def apply(path: Path) -> None:
        path.write_bytes(data)
    return apply


def cases(original: bytes, count: int, seed: int) -> Iterator[Case]:
    """``count`` corruptions of ``original``, the families in turn, drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    n = len(original)
    for i in range(count):
        family = FAMILIES[i % len(FAMILIES)]
        if family == "flip":
            data = bytearray(original)
            where = rng.integers(0, n, size=int(rng.integers(1, 9)))
            for w in where:
                data[w] ^= int(rng.integers(1, 256))
            yield Case(family, f"flip {sorted(where.tolist())}", _write_bytes(bytes(data)))
        elif family == "truncate":
            keep = int(rng.integers(0, n))
            yield Case(family, f"truncate to {keep}", _write_bytes(original[:keep]))
        elif family == "zero":
            start, size = int(rng.integers(0, n)), int(rng.choice([16, 64, 512, 4096]))
            data = bytearray(original)
            data[start : start + size] = bytes(len(data[start : start + size]))
            yield Case(family, f"zero {start}+{size}", _write_bytes(bytes(data)))
        else:
            edits = EDITS if family == "edit" else PLAUSIBLE_EDITS
            what, apply = edits[int(rng.integers(0, len(edits)))]
            yield Case(family, what, lambda p, a=apply, o=original: (p.write_bytes(o), a(p)))


# -- reading ---------------------------------------------------------------------------------


def _same(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape
                and a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))
    return a == b


def _arrays(ds: abco_data.Dataset) -> dict[str, object]:
    return {k: v for k, v in vars(ds.load_arrays()).items()}


def _episodes(ds: abco_data.Dataset) -> list[dict[str, object]]:
    return [{k: v for k, v in vars(ep).items()} for ep in ds.episodes()]


def _torch_items(ds: abco_data.Dataset) -> list[tuple[np.ndarray, ...]]:
    view = ds.torch_dataset()
    try:
        return [tuple(t.numpy() for t in item) for item in view.__getitems__(
            list(range(len(view))))]
    finally:
        view.close()


def _cli_verify(path: Path) -> int:
    from abco_data import cli

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return cli.main(["verify", str(path)])


def read_all(path: Path, reader: str) -> object:
    """What ``reader`` gives for the file at ``path`` (comparable between files)."""
    if reader == "cli_verify":
        return _cli_verify(path)
    if reader == "verify":
        abco_data.verify(path)
        return _arrays(abco_data.open_dataset(path))
    if reader == "check":
        ds = abco_data.check_dataset(path)
        ds.close()
        return _arrays(abco_data.open_dataset(path))
    ds = abco_data.open_dataset(path)
    try:
        if reader == "open":
            return (ds.id, ds.kind, ds.env_id, ds.num_episodes, ds.num_transitions,
                    ds.observation_space, ds.action_space)
        if reader == "load_arrays":
            return _arrays(ds)
        if reader == "episodes":
            return _episodes(ds)
        return _torch_items(ds)
    finally:
        ds.close()


def equal(a: object, b: object) -> bool:
    """Deep equality of what :func:`read_all` returns."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(equal(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(equal(x, y) for x, y in zip(a, b))
    return _same(a, b)


def outcome(path: Path, reader: str, expected: object) -> str:
    """The outcome of one reading (see the module docstring); run in a forked child."""
    try:
        got = read_all(path, reader)
    except DatasetError:
        return "ok-error"
    except Exception as err:  # noqa: BLE001 - what escapes is what we count
        return f"raw:{type(err).__name__}: {str(err)[:120]}"
    if reader == "cli_verify":
        return "ok-error" if got == 2 or got == 1 else ("ok-same" if expected == 0 else "accepted")
    return "ok-same" if equal(got, expected) else "accepted"


def in_child(fn: Callable[[], object], timeout: float) -> object:
    """``fn()`` in a forked child with a time limit: its result, ``hang`` or ``crash:SIG``."""
    outcome = run_in_child(fn, timeout)
    if outcome.timed_out:
        return "hang"
    if not outcome.finished:
        return f"crash:{outcome.signal}"
    if outcome.error is not None:
        return f"raw:{type(outcome.error).__name__}: {outcome.error}"
    return outcome.value


def prepare(directory: Path, dataset_id: str = "abco/maze3x3-pre-v0",
            readers: tuple[str, ...] = READERS, **extra: object) -> tuple[Path, dict]:
    """A small original file and what each reader gives for it."""
    original = make_small(dataset_id, directory, **extra)
    expected = {reader: read_all(original, reader) for reader in readers}
    return original, expected


def _outcomes(path: Path, expected: dict) -> dict[str, str]:
    return {reader: outcome(path, reader, value) for reader, value in expected.items()}


def run(count: int, seed: int, timeout: float = 10.0, dataset_id: str = "abco/maze3x3-pre-v0",
        log: Callable[[str], None] | None = None, readers: tuple[str, ...] = READERS,
        **extra: object) -> Counter:
    """Run ``count`` cases, each in one forked child; return a Counter of
    ``(family, reader, outcome)`` (a hang or crash counts for every reader of its case).

    ``extra`` goes to :func:`data_testing.make_small` (a smaller original, say).
    """
    results: Counter = Counter()
    with tempfile.TemporaryDirectory() as tmp:
        original, expected = prepare(Path(tmp), dataset_id, readers, **extra)
        data = original.read_bytes()
        target = Path(tmp) / "corrupt" / original.name
        target.parent.mkdir()
        for i, case in enumerate(cases(data, count, seed)):
            target.unlink(missing_ok=True)
            try:
                case.apply(target)
            except (KeyError, IndexError):  # a column or row this dataset does not have
                continue
            got = in_child(lambda: _outcomes(target, expected), timeout)
            per_reader = got if isinstance(got, dict) else dict.fromkeys(readers, got)
            for reader, result in per_reader.items():
                if case.family == "plausible" and reader not in CHECKERS:
                    continue
                kind = result if result in (*GOOD, "hang", "accepted") else result.split(":")[0]
                results[(case.family, reader, kind)] += 1
                if result not in GOOD and log is not None:
                    log(f"case {i} {case.family} ({case.what}) {reader}: {result}")
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--timeout", type=float, default=20.0)
    parser.add_argument("--dataset", default="abco/maze3x3-pre-v0")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    results = run(args.cases, args.seed, args.timeout, args.dataset, log=print)
    print(f"{args.cases} cases x {len(READERS)} readers in {time.perf_counter() - start:.0f} s")
    for family in FAMILIES:
        counts = Counter()
        for (fam, _reader, kind), n in results.items():
            if fam == family:
                counts[kind] += n
        print(f"{family:9} " + ", ".join(f"{k}: {v}" for k, v in sorted(counts.items())))
    bad = sum(n for (_, _, kind), n in results.items() if kind not in GOOD)
    print(f"not good: {bad}")
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
