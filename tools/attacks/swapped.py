"""Family 4: a dataset file swapped on disk while it is read.

A torch ``DataLoader`` (two workers, or none) over an ``abco_data`` dataset file A (3x3-maze
pre-demonstrations, or expert data), and A replaced by another valid dataset B: once the
torch view exists, mid-epoch (two epochs), overwritten in place, or replaced by a truncated
copy. Held: every item is A's own (the reader pinned to the file it opened), or every item
B's own, or an error that names the file; never an item mixing both, nor an epoch of both.
"""

from __future__ import annotations

import shutil
import sys
from functools import partial
from pathlib import Path

from attacks.core import Case, Ctx, Outcome, fail, json_line, ok, run_command

FAMILY = "swapped"
PROBE = Path(__file__).with_name("swap_probe.py")


def probe(ctx: Ctx, kind: str, mode: str, workers: int) -> Outcome:
    """Run :mod:`swap_probe` on a copy of the ``kind`` datasets and judge its counts."""
    swap = ctx.fixture("swap")
    base = ctx.scratch(f"swap {kind} {mode} {workers}")
    target = base / "data.hdf5"
    shutil.copy(swap[f"{kind}_a"], target)
    res = run_command([sys.executable, str(PROBE), mode, str(target), swap[f"{kind}_b"],
                       str(workers)], env=ctx.env, timeout=180, memory=ctx.memory,
                      cwd=ctx.root)  # fmt: skip
    if res.timed_out:
        return fail("hang", f"still reading after {res.timeout:.0f} s")
    counts = json_line(res)
    if counts is None:
        return fail("traceback", res.summary())
    seen = f"{counts['items']} items: {counts['a']} of A, {counts['b']} of B, " \
           f"{counts['both']} of both, {counts['mixed']} mixed"  # fmt: skip
    if counts["mixed"]:
        return fail("silent", seen)
    if counts["a"] and counts["b"]:
        return fail("silent", f"{seen} (one read, two files)")
    if "error" in counts:
        if not counts["names_file"]:
            return fail("traceback", f"{counts['error']} does not name the file: "
                        f"{counts['message'][-160:]} ({seen})")  # fmt: skip
        return ok(f"{counts['error']} after {seen}")
    return ok(seen)


def cases() -> list[Case]:
    """Swaps of pre-demonstration and expert files, with and without workers."""
    table = [("pre", "before", 2, True), ("pre", "mid", 2, True), ("pre", "inplace", 2, False),
             ("pre", "truncated", 2, False), ("pre", "before", 0, False),
             ("pre", "mid", 0, False), ("expert", "before", 2, False),
             ("expert", "mid", 2, False)]  # fmt: skip
    return [Case(FAMILY, f"{kind} file, swap {mode}, {workers} workers",
                 partial(probe, kind=kind, mode=mode, workers=workers), quick=quick)
            for kind, mode, workers, quick in table]  # fmt: skip
