"""Attack abco as an attacker and a careless user would, and count what gets through.

The families of the trust issue ("Run folders, grids and downloads you can share and
trust"), each a table of small cases:

1. ``checkpoints``: a pickle payload in ``checkpoint.pt`` (load_policy, play, train, bench);
2. ``outputs``: output paths onto devices, FIFOs, directories and links to them;
3. ``locks``: two writers on one grid or run folder at once;
4. ``swapped``: a dataset file replaced on disk while a DataLoader reads it;
5. ``bounds``: huge ranges, counts and sizes, endless files, a Hub that never answers;
6. ``tracebacks``: damaged and crafted records, bad options, read-only and full disks.

Every command runs in its own process with a hard timeout and a memory limit, its caches
inside the scratch folder (never the user's). The table counts, per family, the cases tried
and those that ended in each failure class: code run, a special file replaced, rows or files
lost, a mixed run folder, silent wrong data, a hang, a traceback (or no clear error line).

Usage::

    .venv/bin/python tools/attack.py --quick           # a representative subset, ~2 min
    .venv/bin/python tools/attack.py                   # every case, 8-15 min on 2 cores
    .venv/bin/python tools/attack.py --families bounds,locks --out /tmp/attack --keep
    .venv/bin/python tools/attack.py --list            # the cases, without running them

Exit status 0 only when no case failed (a gate); 1 otherwise; 2 for bad options.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import shutil
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from attacks import FAMILY_MODULES  # noqa: E402
from attacks.core import FAILURES, LEGEND, PASS, ROOT, SKIP, Case, Ctx, FixtureError, Outcome, fail  # noqa: E402
from attacks.fixtures import FIXTURES  # noqa: E402

FAMILIES = ("checkpoints", "outputs", "locks", "swapped", "bounds", "tracebacks")


def all_cases() -> list[Case]:
    """Every case of every family, in the table's order."""
    cases: list[Case] = []
    for name in FAMILY_MODULES:
        cases += importlib.import_module(name).cases()
    return sorted(cases, key=lambda c: FAMILIES.index(c.family))


def select(cases: Sequence[Case], *, quick: bool, families: Sequence[str] | None,
           match: str | None) -> list[Case]:  # fmt: skip
    """The cases a command line asks for."""
    return [c for c in cases
            if (not quick or c.quick)
            and (families is None or c.family in families)
            and (match is None or match.lower() in f"{c.family} {c.name}".lower())]  # fmt: skip


def run_case(ctx: Ctx, case: Case) -> Outcome:
    """A case's outcome; an error of this script (or of a fixture) is a failure too."""
    try:
        return case.run(ctx)
    except FixtureError as exc:
        return fail("script", f"fixture: {exc}")
    except Exception as exc:  # the script's own bug: counted, never hidden
        where = traceback.extract_tb(exc.__traceback__)[-1]
        return fail("script", f"{type(exc).__name__}: {exc} (tools/{Path(where.filename).name}"
                    f":{where.lineno})")  # fmt: skip


def run_all(ctx: Ctx, cases: Sequence[Case], jobs: int, verbose: bool
            ) -> list[tuple[Case, Outcome, float]]:  # fmt: skip
    """Run the cases, ``jobs`` at a time, printing one line per finished case."""
    done: list[tuple[Case, Outcome, float]] = []
    lock = threading.Lock()
    width = len(str(len(cases)))

    def one(case: Case) -> None:
        t0 = time.monotonic()
        outcome = run_case(ctx, case)
        seconds = time.monotonic() - t0
        with lock:
            done.append((case, outcome, seconds))
            mark = {PASS: "ok", SKIP: "skip"}.get(outcome.verdict, "FAIL")
            line = f"[{len(done):>{width}}/{len(cases)}] {mark:<4} {case.family}: {case.name}"
            if outcome.failed or outcome.verdict == SKIP or verbose:
                line += f" -> {outcome.verdict}: {outcome.detail}"
            print(f"{line} ({seconds:.1f} s)", flush=True)

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        list(pool.map(one, cases))
    order = {id(c): i for i, c in enumerate(cases)}
    return sorted(done, key=lambda d: order[id(d[0])])


def table(results: Sequence[tuple[Case, Outcome, float]]) -> str:
    """Counts per family: cases tried, passed, skipped, and each failure class."""
    heads = ["family", "cases", "passed", "skipped", *FAILURES.values()]
    rows = []
    for family in [*FAMILIES, "total"]:
        mine = [o for c, o, _ in results if family in (c.family, "total")]
        if not mine:
            continue
        rows.append([family, len(mine), sum(o.verdict == PASS for o in mine),
                     sum(o.verdict == SKIP for o in mine),
                     *(sum(o.verdict == k for o in mine) for k in FAILURES)])  # fmt: skip
    widths = [max(len(str(x)) for x in col) for col in zip(heads, *rows)]
    lines = ["  ".join(str(x).rjust(w) if i else str(x).ljust(w)
                       for i, (x, w) in enumerate(zip(row, widths)))
             for row in [heads, *rows]]  # fmt: skip
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def report(results: Sequence[tuple[Case, Outcome, float]], seconds: float) -> str:
    """The table, then one line per failing case, then the skipped ones."""
    out = [table(results), "", *(f"  {FAILURES[k]:<9} {v}" for k, v in LEGEND.items()), ""]
    failing = [(c, o) for c, o, _ in results if o.failed]
    skipped = [(c, o) for c, o, _ in results if o.verdict == SKIP]
    if failing:
        out.append(f"failing cases ({len(failing)}):")
        out += [f"  {c.family} | {c.name} | {o.verdict}: {o.detail}" for c, o in failing]
    if skipped:
        out.append(f"skipped cases ({len(skipped)}):")
        out += [f"  {c.family} | {c.name} | {o.detail}" for c, o in skipped]
    out.append(f"{len(results)} cases in {seconds:.0f} s; "
               + ("no failures" if not failing else f"{len(failing)} failing"))  # fmt: skip
    return "\n".join(out)


def _families(text: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    unknown = [x for x in names if x not in FAMILIES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"unknown families {', '.join(unknown) or '(none given)'}; known: "
            f"{', '.join(FAMILIES)}")  # fmt: skip
    return names


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``tools/attack.py``."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the representative subset only")
    parser.add_argument("--families", type=_families, default=None,
                        help=f"comma-separated: {', '.join(FAMILIES)} (default all)")
    parser.add_argument("-k", "--match", default=None,
                        help="only cases whose 'family name' contains this text")
    parser.add_argument("--out", default=None,
                        help="scratch folder (kept; default a temporary one, removed)")
    parser.add_argument("--keep", action="store_true", help="keep the temporary scratch folder")
    parser.add_argument("--jobs", type=int, default=2, help="cases at once (default 2)")
    parser.add_argument("--memory-gib", type=float, default=4.0,
                        help="address-space limit of every command (default 4 GiB)")
    parser.add_argument("--code", default=None, metavar="DIR",
                        help="the abco checkout to attack (default this repository; e.g. an"
                        " older release, to compare)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--verbose", action="store_true", help="a detail line for every case")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the attack; 0 only when no case failed."""
    args = build_parser().parse_args(argv)
    cases = select(all_cases(), quick=args.quick, families=args.families, match=args.match)
    if args.list:
        for case in cases:
            print(f"{case.family}: {case.name}{'  [quick]' if case.quick else ''}")
        print(f"{len(cases)} cases")
        return 0
    if not cases:
        print("error: no case matches", file=sys.stderr)
        return 2
    root = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="abco-attack-"))
    root.mkdir(parents=True, exist_ok=True)
    root = root.resolve()
    print(f"abco attack: {len(cases)} cases, {args.jobs} at a time, scratch {root}", flush=True)
    ctx = Ctx(root, args.memory_gib, FIXTURES, Path(args.code).resolve() if args.code else ROOT)
    t0 = time.monotonic()
    try:
        results = run_all(ctx, cases, max(1, args.jobs), args.verbose)
    finally:
        from attacks.fixtures import unmount_all

        unmount_all()
    print("\n" + report(results, time.monotonic() - t0))
    (root / "attack_results.json").write_text(json.dumps(
        [{"family": c.family, "case": c.name, "verdict": o.verdict, "detail": o.detail,
          "seconds": round(s, 1)} for c, o, s in results], indent=1))  # fmt: skip
    if not args.out and not args.keep:
        shutil.rmtree(root, ignore_errors=True)
    elif os.environ.get("CI") is None:
        print(f"scratch kept: {root}")
    return 1 if any(o.failed for _, o, _ in results) else 0


if __name__ == "__main__":
    raise SystemExit(main())
