"""Shared fixtures, built once per script run on first use, and the special files and mounts
the cases need.

Device files are never the machine's own: :func:`device` makes a private character device
(``mknod``, as root) with the numbers of ``/dev/null``, ``/dev/zero`` or ``/dev/full`` inside
the scratch folder, so a command that would replace "/dev/full" replaces nothing anyone else
uses. Mounts (a small tmpfs for a full disk, a read-only remount) are made inside the scratch
folder too and undone at exit; where the kernel refuses them the cases are skipped.
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import stat
import subprocess
from contextlib import suppress
from pathlib import Path
from typing import Any

from attacks.core import Ctx, FixtureError, Result

#: Trainer settings of a seconds-long CartPole run (tests/train/test_bench_grid.py's).
TINY = ["--iterations", "1", "--idm-epochs", "1", "--policy-epochs", "1", "--eval-episodes", "3"]
DEVICES = {"null": (1, 3), "zero": (1, 5), "full": (1, 7)}

_mounts: list[Path] = []


def _check(res: Result, what: str) -> None:
    if res.rc != 0:
        raise FixtureError(f"{what} failed: {res.summary()}")


# -- the fixtures ---------------------------------------------------------------------------


def build_data(ctx: Ctx) -> dict[str, str]:
    """Tiny CartPole datasets (2 expert episodes, 500 pre-demonstration transitions)."""
    folder = ctx.root / "fixtures" / "data"
    folder.mkdir(parents=True, exist_ok=True)
    small = ["--set", "reference_episodes=3", "--set", "reference_expert_episodes=2"]
    for name, ds_id, size in (("expert", "abco/cartpole-expert-v0", "episodes=2"),
                              ("pre", "abco/cartpole-pre-v0", "transitions=500")):  # fmt: skip
        res = ctx.abco("data", "generate", ds_id, "--out", str(folder / f"{name}.hdf5"),
                       "--quiet", "--set", size, *small)  # fmt: skip
        _check(res, f"generating the tiny {name} dataset")
    return {"expert": str(folder / "expert.hdf5"), "pre": str(folder / "pre.hdf5")}


def train_flags(ctx: Ctx, method: str = "bco", seed: int = 0) -> list[str]:
    """``abco train`` flags of a tiny CartPole run on the tiny datasets (no ``--run-dir``)."""
    data = ctx.fixture("data")
    return ["--env", "CartPole-v1", "--method", method, "--seed", str(seed),
            "--expert-data", data["expert"], "--pre-data", data["pre"], *TINY,
            "--threads", "1", "--quiet"]  # fmt: skip


def bench_flags(ctx: Ctx) -> list[str]:
    """``abco bench`` trainer overrides of the tiny grid (datasets and budget)."""
    data = ctx.fixture("data")
    return ["--expert-data", data["expert"], "--pre-data", data["pre"], *TINY,
            "--threads", "1", "--quiet"]  # fmt: skip


def build_run(ctx: Ctx) -> Path:
    """A finished tiny CartPole BCO run folder (copy it before changing anything)."""
    run = ctx.root / "fixtures" / "run"
    res = ctx.abco("train", *train_flags(ctx), "--run-dir", str(run))
    _check(res, "the tiny training run")
    if not (run / "final.json").is_file():
        raise FixtureError(f"the tiny training run left no final.json in {run}")
    return run


def build_grid(ctx: Ctx) -> Path:
    """A finished tiny grid: CartPole, BCO, seeds 0 and 1 (copy it before changing it)."""
    out = ctx.root / "fixtures" / "grid"
    res = ctx.abco("bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds", "0-1",
                   "--out", str(out), "--jobs", "2", *bench_flags(ctx))  # fmt: skip
    _check(res, "the tiny grid")
    for seed in (0, 1):
        if not (out / "CartPole-v1" / "bco" / f"seed{seed}" / "final.json").is_file():
            raise FixtureError(f"the tiny grid left no final.json for seed {seed}")
    return out


def build_swap(ctx: Ctx) -> dict[str, str]:
    """Two valid 3x3-maze datasets of each kind that differ (for the swapped-file family)."""
    folder = ctx.root / "fixtures" / "swap"
    folder.mkdir(parents=True, exist_ok=True)
    made = {}
    jobs = {
        "pre_a": ("abco/maze3x3-pre-v0", ["layouts=20", "seed=11"]),
        "pre_b": ("abco/maze3x3-pre-v0", ["layouts=20", "seed=12"]),
        "expert_a": ("abco/maze3x3-expert-v0", ["layouts=20", "solutions_per_layout=4"]),
        "expert_b": ("abco/maze3x3-expert-v0", ["layouts=30", "solutions_per_layout=2"]),
    }
    for name, (ds_id, sets) in jobs.items():
        path = folder / f"{name}.hdf5"
        flags = [x for s in [*sets, "reference_episodes=2"] for x in ("--set", s)]
        _check(ctx.abco("data", "generate", ds_id, "--out", str(path), "--quiet", *flags),
               f"generating {name}")
        made[name] = str(path)
    return made


def build_hub(ctx: Ctx) -> dict[str, Any]:
    """A manifest pinning a Hub revision, and the published bytes of its smallest dataset."""
    folder = ctx.root / "fixtures" / "hub"
    folder.mkdir(parents=True, exist_ok=True)
    ds_id = "abco/maze3x3-expert-v0"
    shipped = json.loads((ctx.code / "abco_data" / "manifest.json").read_text())
    entry = shipped["files"][ds_id]
    data_path = folder / entry["filename"]
    _check(ctx.abco("data", "generate", ds_id, "--out", str(data_path), "--quiet"),
           "generating the Hub's file")
    manifest = folder / "manifest.json"
    revision = "0123456789abcdef0123456789abcdef01234567"
    manifest.write_text(json.dumps({**shipped, "revision": revision, "files": {ds_id: entry}}))
    return {"id": ds_id, "entry": entry, "manifest": str(manifest), "revision": revision,
            "data": data_path.read_bytes()}  # fmt: skip


FIXTURES = {"data": build_data, "run": build_run, "grid": build_grid, "swap": build_swap,
            "hub": build_hub}  # fmt: skip


# -- copies ---------------------------------------------------------------------------------


def copy_run(ctx: Ctx, dest: Path, *, final: bool = True) -> Path:
    """A copy of the trained run at ``dest`` (without ``final.json`` unless ``final``)."""
    source = ctx.fixture("run")
    shutil.copytree(source, dest)
    _retarget(dest, source)
    if not final:
        (dest / "final.json").unlink()
    return dest


def copy_grid(ctx: Ctx, dest: Path) -> Path:
    """A copy of the tiny grid at ``dest`` (its report folder left out)."""
    source = ctx.fixture("grid")
    shutil.copytree(source, dest, ignore=shutil.ignore_patterns("report"))
    _retarget(dest, source)
    return dest


def _retarget(dest: Path, source: Path) -> None:
    """Each ``config.json`` of a copy names the copy as its run folder, as the trainer would
    write it there (so a command that rewrites it unchanged changes nothing)."""
    for config in [dest / "config.json", *dest.glob("*/*/seed*/config.json")]:
        if config.is_file():
            config.write_text(config.read_text().replace(str(source), str(dest)))


# -- special files and mounts ---------------------------------------------------------------


def device(path: Path, name: str) -> bool:
    """A private character device with the numbers of ``/dev/{name}`` at ``path``; False
    where ``mknod`` is not allowed (not root)."""
    major, minor = DEVICES[name]
    try:
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(major, minor))
    except (PermissionError, OSError):
        return False
    return True


def same_device(path: Path, name: str) -> bool:
    """``path`` is still (not through a link) the character device ``name``."""
    try:
        st = path.lstat()
    except FileNotFoundError:
        return False
    return stat.S_ISCHR(st.st_mode) and st.st_rdev == os.makedev(*DEVICES[name])


def sparse(path: Path, size: int) -> Path:
    """A sparse file of ``size`` bytes (zeros; nothing allocated on disk)."""
    with path.open("wb") as f:
        f.truncate(size)
    return path


def mount_tmpfs(path: Path, size_kib: int) -> bool:
    """Mount a tmpfs of ``size_kib`` KiB on ``path``; False where mounting is not allowed."""
    path.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs",
                           str(path)], capture_output=True)  # fmt: skip
    if done.returncode != 0:
        return False
    _mounts.append(path)
    return True


def remount_readonly(path: Path) -> bool:
    """Make a mount of :func:`mount_tmpfs` read-only."""
    done = subprocess.run(["mount", "-o", "remount,ro", str(path)], capture_output=True)
    return done.returncode == 0


def unmount(path: Path) -> None:
    """Undo :func:`mount_tmpfs` (lazily, so an open file cannot keep it)."""
    if path in _mounts:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)
        _mounts.remove(path)


def fill(path: Path, leave: int) -> None:
    """Fill the filesystem of ``path`` until about ``leave`` bytes are free."""
    free = shutil.disk_usage(path).free
    if free > leave:
        with (path / ".filler").open("wb") as f, suppress(OSError):  # full: as wanted
            f.write(b"\0" * (free - leave))


@atexit.register
def unmount_all() -> None:
    """Undo every mount this run made."""
    for path in list(reversed(_mounts)):
        unmount(path)
