"""Family 6, part three: bad options and arguments, plugins, a closed stdout, read-only and
full disks.

Each bad input runs as a command line (tiny datasets and budget, so one wrongly accepted
ends in seconds). Held: exit 1 or 2 with exactly one ``error:`` line on stderr, nothing that
looks like a traceback; exit 0 is "silent wrong" (``--lr inf`` trained, ``--envs ''`` ran
nothing). A closed stdout (``| head``): no traceback. Read-only folders (a tmpfs remounted
read-only) and full disks (a small tmpfs): one line, every file that was there unchanged,
no 0-byte file left; skipped where mounting is not allowed.
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

from attacks.core import (
    TRACEBACK,
    Case,
    Ctx,
    Outcome,
    fail,
    kept,
    ok,
    refused,
    run_command,
    skip,
    snapshot,
    telling_line,
)
from attacks.fixtures import (
    bench_flags,
    copy_grid,
    copy_run,
    fill,
    mount_tmpfs,
    remount_readonly,
    train_flags,
    unmount,
)

FAMILY = "tracebacks"
Build = Callable[[Ctx, Path], list[str]]


def _fill(args: tuple[str, ...], base: Path) -> list[str]:
    """The arguments with ``{base}`` replaced by the case's folder."""
    return [x.replace("{base}", str(base)) for x in args]


def T(*extra: str) -> Build:  # noqa: N802 - a table's shorthand
    """``abco train`` on the tiny datasets, in a fresh run folder, with ``extra`` last."""
    return lambda ctx, base: ["train", *train_flags(ctx), "--run-dir", str(base / "run"),
                              *_fill(extra, base)]  # fmt: skip


def B(*extra: str) -> Build:  # noqa: N802 - a table's shorthand
    """``abco bench`` of one tiny cell into a fresh grid, with ``extra`` last."""
    return lambda ctx, base: ["bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds",
                              "0", "--jobs", "1", "--out", str(base / "grid"), *bench_flags(ctx),
                              *_fill(extra, base)]  # fmt: skip


def P(*extra: str) -> Build:  # noqa: N802 - a table's shorthand
    """``abco play`` on a copy of the trained run, with ``extra`` last."""

    def build(ctx: Ctx, base: Path) -> list[str]:
        run = copy_run(ctx, base / "run")
        return ["play", str(run), "--quiet", "--out", str(base / "p.gif"),
                *_fill(extra, base)]  # fmt: skip

    return build


def R(*extra: str, grid: bool = True) -> Build:  # noqa: N802 - a table's shorthand
    """``abco report`` (on a copy of the tiny grid unless the extra arguments name one)."""

    def build(ctx: Ctx, base: Path) -> list[str]:
        folder = copy_grid(ctx, base / "grid") if grid else base / "grid"
        return ["report", *([str(folder)] if grid else []),
                *_fill(extra, base)]  # fmt: skip

    return build


def D(*args: str) -> Build:  # noqa: N802 - a table's shorthand
    """``abco data ARGS`` (``{base}`` is the case's folder)."""
    return lambda ctx, base: ["data", *_fill(args, base)]


def _files(base: Path) -> None:
    """The odd files a row may name: garbage, an empty file, a folder, plugins."""
    (base / "garbage.hdf5").write_bytes(b"this is not HDF5\n" * 64)
    (base / "empty.hdf5").write_bytes(b"")
    (base / "folder.hdf5").mkdir()
    (base / "notes.txt").write_text("a user's notes\n")
    (base / "nothing.py").write_text("x = 1  # registers no method\n")
    (base / "broken.py").write_text("def (:\n")
    (base / "raising.py").write_text("raise RuntimeError('plugin failed on purpose')\n")
    (base / "plugin_dir.py").mkdir()


def T0(*extra: str) -> Build:  # noqa: N802 - a table's shorthand
    """``abco train`` on the tiny datasets without method options (for another method)."""

    def build(ctx: Ctx, base: Path) -> list[str]:
        data = ctx.fixture("data")
        return ["train", "--env", "CartPole-v1", "--expert-data", data["expert"], "--pre-data",
                data["pre"], "--iterations", "1", "--eval-episodes", "3", "--threads", "1",
                "--quiet", "--run-dir", str(base / "run"), *_fill(extra, base)]  # fmt: skip

    return build


def B0(*extra: str) -> Build:  # noqa: N802 - a table's shorthand
    """``abco bench`` of one cell with no method options (a grid that may turn out empty)."""
    return lambda ctx, base: ["bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds",
                              "0", "--jobs", "1", "--threads", "1", "--quiet", "--out",
                              str(base / "grid"), *_fill(extra, base)]  # fmt: skip


def _push(repo: str) -> Build:
    """``abco data push`` of a published file (so the file passes its checks) to ``repo``."""

    def build(ctx: Ctx, base: Path) -> list[str]:
        hub = ctx.fixture("hub")
        path = base / hub["entry"]["filename"]
        path.write_bytes(hub["data"])
        return ["data", "push", hub["id"], "--repo", repo, "--path", str(path)]

    return build


#: name -> (command line, quick[, a word the error line must hold])
ROWS: dict[str, tuple[Build, bool] | tuple[Build, bool, str]] = {
    # abco train: options
    "train --lr nan": (T("--lr", "nan"), True),
    "train --lr inf": (T("--lr", "inf"), True),
    "train --lr -inf": (T("--lr=-inf"), False),
    "train --lr -1": (T("--lr", "-1"), False),
    "train --lr 0": (T("--lr", "0"), False),
    "train --lr 1e999": (T("--lr", "1e999"), False),
    "train --lr abc": (T("--lr", "abc"), False),
    "train --batch-size 0": (T("--batch-size", "0"), False),
    "train --batch-size 1.5": (T("--batch-size", "1.5"), False),
    "train --seed -1": (T("--seed", "-1"), False),
    "train --seed 99999999999999999999999": (T("--seed", "99999999999999999999999"), True),
    "train --seed abc": (T("--seed", "abc"), False),
    "train --iterations -1": (T("--iterations", "-1"), False),
    "train --eval-episodes 0": (T("--eval-episodes", "0"), False),
    "train --idm-epochs 0": (T("--idm-epochs", "0"), False),
    "train --method nosuch": (T0("--method", "nosuch"), False, "nosuch"),
    "train --env NoSuch-v0": (T("--env", "NoSuch-v0"), False),
    "train --env ''": (T("--env", ""), False),
    "train --preset nosuch": (T("--preset", "nosuch"), False),
    "train --regime nosuch": (T("--regime", "nosuch"), False),
    "train --arch nosuch": (T("--arch", "nosuch"), False),
    "train --arch resnet18 on state vectors": (T("--arch", "resnet18"), False),
    "train --device nosuch": (T("--device", "nosuch"), False),
    "train --protocol nosuch": (T("--protocol", "nosuch"), False),
    "train --method-options unknown key": (T("--method-options", '{"nosuch": 1}'), True),
    "train --method-options not JSON": (T("--method-options", "{nosuch"), False),
    "train --method-options a list": (T("--method-options", "[1]"), False),
    "train --method-options idm_patience 'x'": (T("--method-options", '{"idm_patience": "x"}'),
                                               False),
    "train --method-options idm_patience -1": (T("--method-options", '{"idm_patience": -1}'),
                                               False),
    "train --method-options idm_patience 1e999": (
        T("--method-options", '{"idm_patience": 1e999}'), False),
    "train --method-options idm_patience NaN": (T("--method-options", '{"idm_patience": NaN}'),
                                                False),
    "train --method-options deeply nested": (T("--method-options", "[" * 20000 + "]" * 20000),
                                             False),
    # abco train: files
    "train --expert-data a missing file": (T("--expert-data", "{base}/missing.hdf5"), False),
    "train --expert-data garbage": (T("--expert-data", "{base}/garbage.hdf5"), False),
    "train --expert-data an empty file": (T("--expert-data", "{base}/empty.hdf5"), False),
    "train --expert-data a folder": (T("--expert-data", "{base}/folder.hdf5"), False),
    "train --expert-data an unknown id": (T("--expert-data", "abco/nosuch-v0"), False),
    "train --pre-data the expert file (wrong kind)": (
        lambda ctx, base: T("--pre-data", ctx.fixture("data")["expert"])(ctx, base), False),
    "train --expert-data of another env": (
        lambda ctx, base: T("--expert-data", ctx.fixture("swap")["expert_a"])(ctx, base), False),
    "train --run-dir a regular file": (T("--run-dir", "{base}/notes.txt"), False),
    "train --cache-dir a regular file, default data": (
        lambda ctx, base: ["train", "--env", "CartPole-v1", "--run-dir", str(base / "run"),
                           "--cache-dir", str(base / "notes.txt"), "--quiet"], False),
    # plugins
    "train --plugin that registers nothing": (T("--plugin", "{base}/nothing.py"), True),
    "train --plugin with a syntax error": (T("--plugin", "{base}/broken.py"), False),
    "train --plugin raising at import": (T("--plugin", "{base}/raising.py"), False),
    "train --plugin a missing file": (T("--plugin", "{base}/missing.py"), False),
    "train --plugin a missing module": (T("--plugin", "no_such_module_xyz"), False),
    "train --plugin a folder named .py": (T("--plugin", "{base}/plugin_dir.py"), False),
    "bench --plugin that registers nothing": (B("--plugin", "{base}/nothing.py"), False),
    # abco bench
    "bench --envs ''": (B0("--envs", ""), True),
    "bench --envs ','": (B0("--envs", ","), False),
    "bench --methods ''": (B0("--methods", ""), False),
    "bench --seeds ''": (B("--seeds", ""), False),
    "bench --seeds x": (B("--seeds", "x"), False),
    "bench --seeds 5-2": (B("--seeds", "5-2"), False),
    "bench --seeds -1": (B("--seeds=-1"), False),
    "bench --seeds 0-": (B("--seeds", "0-"), False),
    "bench --seeds ٣": (B("--seeds", "٣"), False),
    "bench --envs NoSuch-v0": (B("--envs", "NoSuch-v0"), False),
    "bench --methods nosuch": (B("--methods", "nosuch"), False),
    "bench --layouts x": (B("--layouts", "x"), False),
    "bench --layouts 0": (B("--layouts", "0", "--envs", "AbcoMaze5x5-v0"), False),
    "bench --layouts on CartPole": (B("--layouts", "100"), False),
    "bench --jobs 0": (B("--jobs", "0"), False),
    "bench --threads 0": (B("--threads", "0"), False),
    "bench --backend ray (not installed)": (B("--backend", "ray"), False),
    "bench --out a regular file": (B("--out", "{base}/notes.txt"), False),
    "bench --method-options unknown key": (B("--method-options", '{"nosuch": 1}'), False),
    "bench --lr inf": (B("--lr", "inf"), False),
    # abco report
    "report on a missing folder": (R("{base}/missing", grid=False), False),
    "report on a regular file": (R("{base}/notes.txt", grid=False), False),
    "report on an empty folder": (R("{base}/folder.hdf5", grid=False), False),
    "report --baseline nosuch": (R("--baseline", "nosuch", "--out", "{base}/report"), False),
    "report --labels-env NoSuch-v0": (R("--labels-env", "NoSuch-v0", "--out", "{base}/report"),
                                      False),
    "report --out a regular file": (R("--out", "{base}/notes.txt"), False),
    # abco play
    "play on a missing folder": (lambda ctx, base: ["play", str(base / "missing"), "--quiet"],
                                 False),
    "play on an empty folder": (lambda ctx, base: ["play", str(base / "folder.hdf5"), "--quiet"],
                                False),
    "play on a regular file": (lambda ctx, base: ["play", str(base / "notes.txt"), "--quiet"],
                               False),
    "play --episodes x": (P("--episodes", "x"), False),
    "play --episodes 3-1": (P("--episodes", "3-1"), False),
    "play --episodes ''": (P("--episodes", ""), False),
    "play --episodes -1": (P("--episodes=-1"), False),
    "play --out under a regular file": (P("--out", "{base}/notes.txt/p.gif"), False),
    "play --max-steps 0": (P("--max-steps", "0"), False),
    "play --fps 0": (P("--fps", "0"), False),
    # abco data
    "data info nosuch": (D("info", "abco/nosuch-v0"), False),
    "data info a garbage file": (D("info", "{base}/garbage.hdf5"), False),
    "data info --layouts 0": (D("info", "abco/maze5x5-expert-v0", "--layouts", "0"), False),
    "data generate nosuch": (D("generate", "abco/nosuch-v0", "--out", "{base}/x.hdf5"), False),
    "data generate --set nosuch=1": (D("generate", "abco/cartpole-expert-v0", "--out",
                                       "{base}/x.hdf5", "--set", "nosuch=1"), False),
    "data generate --set without =": (D("generate", "abco/cartpole-expert-v0", "--out",
                                        "{base}/x.hdf5", "--set", "episodes"), False),
    "data generate --set layouts=x": (D("generate", "abco/maze3x3-pre-v0", "--out",
                                        "{base}/x.hdf5", "--set", "layouts=x"), False),
    "data generate --set episodes=0": (D("generate", "abco/cartpole-expert-v0", "--out",
                                         "{base}/x.hdf5", "--set", "episodes=0"), False),
    "data generate --set seed=-1": (D("generate", "abco/cartpole-expert-v0", "--out",
                                      "{base}/x.hdf5", "--set", "seed=-1"), False),
    "data verify a garbage file": (D("verify", "{base}/garbage.hdf5"), False),
    "data verify a missing file": (D("verify", "{base}/missing.hdf5"), False),
    "data verify a folder": (D("verify", "{base}/folder.hdf5"), False),
    "data verify --timeout nan": (D("verify", "{base}/garbage.hdf5", "--timeout", "nan"), False),
    "data push --repo ../../x": (_push("../../x"), True, "repo"),
    "data push --repo 'a b'": (_push("a b"), False, "repo"),
    "data push nosuch": (D("push", "abco/nosuch-v0", "--repo", "o/n"), False),
    "data download nosuch": (D("download", "abco/nosuch-v0"), False),
    "data download, offline and unpublished": (D("download", "abco/cartpole-expert-v0"), False),
    "convert-checkpoint on a missing folder": (
        lambda ctx, base: ["convert-checkpoint", str(base / "missing")], False),
    "convert-checkpoint on an empty folder": (
        lambda ctx, base: ["convert-checkpoint", str(base / "folder.hdf5")], False),
}  # fmt: skip


def row_case(ctx: Ctx, name: str, build: Build, mention: str | None = None) -> Outcome:
    base = ctx.scratch(name)
    _files(base)
    argv = build(ctx, base)
    before = snapshot(base)
    res = ctx.abco(*argv, timeout=120)
    return kept(before, base, refused(res, mention=mention))


# -- a closed stdout ------------------------------------------------------------------------


def closed_stdout(ctx: Ctx, name: str, build: Build) -> Outcome:
    """The command's stdout is a pipe whose reader is gone (``| true``, or ``| head -n 1``)."""
    base = ctx.scratch(name)
    argv = [sys.executable, "-m", "abco_train", *build(ctx, base)]
    reader = "head -n 1" if "head" in name else "true"
    shell = f"{shlex.join(argv)} | {reader}"
    res = run_command(["bash", "-o", "pipefail", "-c", shell], env=ctx.env, timeout=120,
                      memory=ctx.memory, cwd=ctx.root)  # fmt: skip
    if res.timed_out:
        return fail("hang", f"still running after {res.timeout:.0f} s")
    if TRACEBACK.search(res.err):
        return fail("traceback", telling_line(res.err))
    lines = [x for x in res.err.splitlines() if x.strip()]
    if len(lines) > 1:
        return fail("traceback", f"{len(lines)} lines on stderr: {lines[-1][:150]}")
    return ok(f"exit {res.rc}{': ' + lines[0] if lines else ''}")


PIPES: dict[str, Build] = {
    "data list | true": lambda ctx, base: ["data", "list"],
    "data list | head -n 1": lambda ctx, base: ["data", "list"],
    "--help | true": lambda ctx, base: ["--help"],
    "train --help | true": lambda ctx, base: ["train", "--help"],
    "report | true": lambda ctx, base: ["report", str(copy_grid(ctx, base / "grid")), "--out",
                                        str(base / "report")],
    "data info ID | true": lambda ctx, base: ["data", "info", "abco/maze5x5-expert-v0"],
}  # fmt: skip


# -- read-only and full disks ---------------------------------------------------------------


def _zero_byte_files(path: Path) -> list[str]:
    """Empty files under ``path`` (lock files, empty by nature, aside)."""
    return sorted(p.relative_to(path).as_posix() for p in path.rglob("*")
                  if p.is_file() and not p.is_symlink() and p.stat().st_size == 0
                  and p.name != ".filler" and not p.name.endswith(".lock"))  # fmt: skip


def disk_case(ctx: Ctx, name: str, setup: Callable[[Ctx, Path], list[str]], *, readonly: bool,
              size_kib: int = 65536, leave: int | None = None) -> Outcome:  # fmt: skip
    """Mount a tmpfs at ``base/mnt``, let ``setup`` fill it and give the command line, make
    it read-only (or fill it to ``leave`` free bytes), run, and judge."""
    base = ctx.scratch(name)
    mnt = base / "mnt"
    if not mount_tmpfs(mnt, size_kib):
        return skip("mounting a tmpfs is not allowed here")
    try:
        argv = setup(ctx, mnt)
        if readonly and not remount_readonly(mnt):
            return skip("remounting read-only is not allowed here")
        if leave is not None:
            fill(mnt, leave)
        zero_before = set(_zero_byte_files(mnt))
        before = snapshot(mnt)
        res = ctx.abco(*argv, timeout=150)
        outcome = kept(before, mnt, refused(res))
        zero = sorted(set(_zero_byte_files(mnt)) - zero_before)
        if zero and not outcome.failed:
            return fail("lost", f"0-byte files left: {', '.join(zero[:3])}")
        return outcome
    finally:
        unmount(mnt)


def _ro_resume(ctx: Ctx, mnt: Path) -> list[str]:
    run = copy_run(ctx, mnt / "run", final=False)
    return ["train", *train_flags(ctx), "--run-dir", str(run)]


def _ro_play(ctx: Ctx, mnt: Path) -> list[str]:
    return ["play", str(copy_run(ctx, mnt / "run")), "--episodes", "0", "--quiet"]


def _ro_report(ctx: Ctx, mnt: Path) -> list[str]:
    return ["report", str(copy_grid(ctx, mnt / "grid"))]


def _ro_bench(ctx: Ctx, mnt: Path) -> list[str]:
    grid = copy_grid(ctx, mnt / "grid")
    return ["bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds", "0-1", "--out",
            str(grid), "--jobs", "1", *bench_flags(ctx)]  # fmt: skip


def _generate_into(ctx: Ctx, mnt: Path) -> list[str]:
    return ["data", "generate", "abco/cartpole-expert-v0", "--out", str(mnt / "x.hdf5"),
            "--quiet", "--set", "episodes=20"]  # fmt: skip


def _fresh_train(ctx: Ctx, mnt: Path) -> list[str]:
    return ["train", *train_flags(ctx), "--run-dir", str(mnt / "run")]


def _fresh_bench(ctx: Ctx, mnt: Path) -> list[str]:
    return ["bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds", "0", "--out",
            str(mnt / "grid"), "--jobs", "1", *bench_flags(ctx)]  # fmt: skip


def _full_report(ctx: Ctx, mnt: Path) -> list[str]:
    grid = copy_grid(ctx, mnt.parent / "grid")
    return ["report", str(grid), "--out", str(mnt / "report")]


def _full_play(ctx: Ctx, mnt: Path) -> list[str]:
    run = copy_run(ctx, mnt.parent / "run")
    return ["play", str(run), "--episodes", "0-3", "--quiet", "--out", str(mnt / "p.gif")]


DISKS: dict[str, tuple[Callable[[Ctx, Path], list[str]], dict[str, int | bool], bool]] = {
    "read-only run folder: train resumes": (_ro_resume, {"readonly": True}, True),
    "read-only run folder: play": (_ro_play, {"readonly": True}, False),
    "read-only grid: report": (_ro_report, {"readonly": True}, False),
    "read-only grid: bench": (_ro_bench, {"readonly": True}, False),
    "read-only folder: data generate --out": (_generate_into, {"readonly": True}, False),
    "read-only folder: train into a new run folder": (_fresh_train, {"readonly": True}, False),
    "full disk: train, at the checkpoint": (_fresh_train, {"readonly": False, "size_kib": 16},
                                            True),
    "full disk: train resumes, at final.json and the plots": (
        _ro_resume, {"readonly": False, "leave": 2048}, False),
    "full disk: bench into a new grid": (_fresh_bench, {"readonly": False, "size_kib": 16},
                                         False),
    "full disk: report --out": (_full_report, {"readonly": False, "size_kib": 8}, False),
    "full disk: play --out": (_full_play, {"readonly": False, "size_kib": 8}, False),
    "full disk: data generate --out": (_generate_into, {"readonly": False, "size_kib": 16},
                                       False),
}  # fmt: skip


def cases() -> list[Case]:
    """The table of bad inputs, the closed pipes, the read-only and full disks."""
    out = [Case(FAMILY, name, partial(row_case, name=name, build=row[0],
                                      mention=row[2] if len(row) > 2 else None), quick=row[1])
           for name, row in ROWS.items()]  # fmt: skip
    out += [Case(FAMILY, f"closed stdout: {name}", partial(closed_stdout, name=name,
                                                           build=build),
                 quick=name == "data list | true") for name, build in PIPES.items()]  # fmt: skip
    out += [Case(FAMILY, name, partial(disk_case, name=name, setup=setup, **options),
                 quick=quick) for name, (setup, options, quick) in DISKS.items()]  # fmt: skip
    return out
