"""Family 2: output paths onto special files.

``abco data generate --out``, ``abco train --run-dir``, ``abco play --out``, ``abco report
--out``, ``abco bench --out`` and ``abco_data.generate`` pointed at a character device (a
private copy of ``/dev/full`` or ``/dev/null``), a FIFO, a directory, a regular file where a
folder is expected, a link to one of those, or a run folder or grid whose output files are
such things. Held: the special file is still what it was (``os.lstat``: a character device
with the same numbers, a FIFO, a directory with its contents), nothing else that was there
changed, and the command ended with one ``error:`` line.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import partial
from pathlib import Path

from attacks.core import (
    Case,
    Ctx,
    Outcome,
    Result,
    changed,
    fail,
    json_line,
    kind_of,
    ok,
    refused,
    skip,
    snapshot,
)
from attacks.fixtures import bench_flags, copy_grid, copy_run, device, same_device, train_flags

FAMILY = "outputs"
GENERATE = ["data", "generate", "abco/cartpole-expert-v0", "--quiet", "--set", "episodes=2",
            "--set", "reference_episodes=2", "--set", "reference_expert_episodes=2"]  # fmt: skip


def make(kind: str, path: Path) -> Callable[[], bool] | None:
    """Create a special file of ``kind`` at ``path``; a check that it is still there and
    unchanged (``None`` where this kind cannot be made here)."""
    if kind in ("full", "null", "zero"):
        if not device(path, kind):
            return None
        return lambda: same_device(path, kind)
    if kind == "fifo":
        os.mkfifo(path)
        return lambda: kind_of(path) == "fifo"
    if kind in ("dir", "dir with a file"):
        path.mkdir()
        if kind == "dir with a file":
            (path / "keep.txt").write_text("keep me")
        return lambda: kind_of(path) == "dir" and (
            kind == "dir" or (path / "keep.txt").read_text() == "keep me")
    if kind == "file":
        path.write_text("a user's notes\n")
        return lambda: kind_of(path) == "file" and path.read_text() == "a user's notes\n"
    if kind.startswith("link to "):
        target = path.parent / f"{path.name}.target"
        inner = make(kind[len("link to "):], target)
        if inner is None:
            return None
        path.symlink_to(target)
        return lambda: kind_of(path) == "link" and inner()
    raise ValueError(kind)


def judge(res: Result, intact: Callable[[], bool], what: str, *, may_succeed: bool = False
          ) -> Outcome:  # fmt: skip
    """The special file untouched and the command refused (or, where writing into a
    directory is a fair reading, succeeded beside its contents)."""
    if not intact():
        return fail("special", f"{what} was replaced or written ({res.summary()})")
    if may_succeed and res.rc == 0:
        return ok("wrote beside it")
    return refused(res)


def _target(ctx: Ctx, name: str, kind: str) -> tuple[Path, Path, Callable[[], bool] | None]:
    base = ctx.scratch(name)
    path = base / "target"
    return base, path, make(kind, path)


def generate_out(ctx: Ctx, kind: str) -> Outcome:
    base, path, intact = _target(ctx, f"generate {kind}", kind)
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    res = ctx.abco(*GENERATE, "--out", str(path), timeout=60)
    return judge(res, intact, f"--out ({kind})", may_succeed=kind.startswith("dir"))


def generate_api(ctx: Ctx, kind: str) -> Outcome:
    base, path, intact = _target(ctx, f"generate() {kind}", kind)
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    code = ("import json, sys, abco_data\n"
            "try:\n"
            "    abco_data.generate('abco/cartpole-expert-v0', sys.argv[1], progress=False,"
            " episodes=2, reference_episodes=2, reference_expert_episodes=2)\n"
            "except Exception as exc:\n"
            "    print(json.dumps({'error': type(exc).__name__, 'message': str(exc)}))\n"
            "else:\n"
            "    print(json.dumps({'written': True}))\n")  # fmt: skip
    res = ctx.python(code, str(path), timeout=60)
    if not intact():
        return fail("special", f"generate() replaced the {kind} ({res.summary()})")
    answer = json_line(res)
    if res.timed_out:
        return fail("hang", f"still running after {res.timeout:.0f} s")
    if answer is None:
        return fail("traceback", res.summary())
    if answer.get("written"):
        return fail("silent", f"generate() reported success onto a {kind}")
    return ok(f"{answer['error']}: {answer['message'][:150]}")


def train_run_dir(ctx: Ctx, kind: str) -> Outcome:
    base, path, intact = _target(ctx, f"train run-dir {kind}", kind)
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    res = ctx.abco("train", *train_flags(ctx), "--run-dir", str(path), timeout=90)
    return judge(res, intact, f"--run-dir ({kind})")


def train_output_inside(ctx: Ctx, name: str, kind: str) -> Outcome:
    """A fresh run folder whose output file ``name`` is already a special file."""
    base = ctx.scratch(f"train {name} {kind}")
    run = base / "run"
    run.mkdir()
    intact = make(kind, run / name)
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    res = ctx.abco("train", *train_flags(ctx), "--run-dir", str(run), timeout=90)
    return judge(res, intact, f"the run folder's {name} ({kind})")


def play_out(ctx: Ctx, kind: str) -> Outcome:
    base, path, intact = _target(ctx, f"play out {kind}", kind)
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    run = copy_run(ctx, base / "run")
    before = snapshot(run)
    res = ctx.abco("play", str(run), "--episodes", "0", "--quiet", "--out", str(path),
                   timeout=90)  # fmt: skip
    outcome = judge(res, intact, f"--out ({kind})")
    gone = changed(before, run)
    return fail("lost", f"changed: {gone[:3]}") if gone and not outcome.failed else outcome


def _special_target(base: Path, kind: str, inside: str | None, folder: str
                    ) -> tuple[Path, Callable[[], bool] | None]:  # fmt: skip
    """An output path that is a special file of ``kind`` (``inside`` ``None``), or a new
    ``folder`` whose file ``inside`` is one; with :func:`make`'s record of it."""
    if inside is None:
        return base / "target", make(kind, base / "target")
    path = base / folder
    path.mkdir()
    return path, make(kind, path / inside)


def report_out(ctx: Ctx, kind: str, inside: str | None = None) -> Outcome:
    """``abco report --out`` a special file, or a folder whose ``inside`` file is one."""
    base = ctx.scratch(f"report out {kind} {inside}")
    grid = copy_grid(ctx, base / "grid")
    path, intact = _special_target(base, kind, inside, "report")
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    res = ctx.abco("report", str(grid), "--out", str(path), timeout=60)
    return judge(res, intact, f"report {inside or '--out'} ({kind})")


def bench_out(ctx: Ctx, kind: str, inside: str | None = None) -> Outcome:
    """``abco bench --out`` a special file, or a grid whose ``inside`` file is one."""
    base = ctx.scratch(f"bench out {kind} {inside}")
    path, intact = _special_target(base, kind, inside, "grid")
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    res = ctx.abco("bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds", "0",
                   "--out", str(path), "--jobs", "1", *bench_flags(ctx), timeout=120)  # fmt: skip
    return judge(res, intact, f"bench {inside or '--out'} ({kind})")


def cache_file(ctx: Ctx, kind: str) -> Outcome:
    """The dataset cache's file is a special file when ``abco data generate ID`` writes it."""
    base = ctx.scratch(f"cache file {kind}")
    cache = base / "cache"
    cache.mkdir()
    intact = make(kind, cache / "cartpole-expert-v0.hdf5")
    if intact is None:
        return skip("mknod is not allowed here (not root)")
    env = {**ctx.env, "ABCO_DATA_HOME": str(cache)}
    res = ctx.abco("data", "generate", "abco/cartpole-expert-v0", "--quiet", env=env,
                   timeout=120)  # fmt: skip
    return judge(res, intact, f"the cache's file ({kind})")


def cases() -> list[Case]:
    """About thirty outputs onto special files."""
    table: list[tuple[str, Callable[[Ctx], Outcome], bool]] = []
    for kind in ("full", "null", "fifo", "dir", "dir with a file", "link to full",
                 "link to fifo"):  # fmt: skip
        table.append((f"data generate --out {kind}", partial(generate_out, kind=kind),
                      kind == "full"))  # fmt: skip
    for kind in ("full", "fifo"):
        table.append((f"abco_data.generate() onto {kind}", partial(generate_api, kind=kind),
                      False))  # fmt: skip
    for kind in ("null", "fifo", "file", "link to null"):
        table.append((f"train --run-dir {kind}", partial(train_run_dir, kind=kind),
                      kind == "null"))  # fmt: skip
    for name, kind in (("metrics.jsonl", "fifo"), ("config.json", "link to full"),
                       ("final.json", "full"), ("metrics.png", "dir with a file"),
                       ("checkpoint.pt", "null")):  # fmt: skip
        table.append((f"train, run folder's {name} is {kind}",
                      partial(train_output_inside, name=name, kind=kind), False))
    for kind in ("full", "fifo", "dir with a file", "link to null"):
        table.append((f"play --out {kind}", partial(play_out, kind=kind), False))
    for kind, inside in (("full", None), ("fifo", None), ("file", None), ("fifo", "report.md"),
                         ("full", "results.csv")):  # fmt: skip
        table.append((f"report --out {inside + ' is ' if inside else ''}{kind}",
                      partial(report_out, kind=kind, inside=inside), False))
    for kind, inside in (("null", None), ("fifo", "results.jsonl"),
                         ("full", "bench_log.jsonl")):  # fmt: skip
        table.append((f"bench --out {inside + ' is ' if inside else ''}{kind}",
                      partial(bench_out, kind=kind, inside=inside), False))
    for kind in ("fifo", "full"):
        table.append((f"data generate ID, cache file is {kind}", partial(cache_file, kind=kind),
                      False))  # fmt: skip
    return [Case(FAMILY, name, run, quick=quick) for name, run, quick in table]
