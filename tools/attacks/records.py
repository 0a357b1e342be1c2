"""Family 6, part one: damaged and crafted records of grids.

``abco report`` on a copy of a finished tiny grid (two CartPole BCO cells) with one record
damaged or crafted: ``results.jsonl``, ``bench_log.jsonl``, a cell's ``final.json`` or
``metrics.jsonl``, odd seed folders (``seed²``, ``seed٣``, ``seed00``), text with control
characters. Held: exit 0 with the bad record named (and not counted: the csv's seed counts and
numbers stay those of the good runs, finite), or one ``error:`` line; no raw control
character printed.
"""

from __future__ import annotations

import csv
import io
import json
import math
import shutil
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from attacks.core import (
    TRACEBACK,
    Case,
    Ctx,
    Outcome,
    fail,
    ok,
    refused,
)
from attacks.fixtures import copy_grid

FAMILY = "tracebacks"
SEED0 = "CartPole-v1/bco/seed0"
NESTED = "[" * 100000 + "]" * 100000
FORGED = "local\x1b[2J\x1b[31m\nerror: forged line\r"


# -- report on damaged grids ----------------------------------------------------------------


def edit_json(path: Path, edit: Callable[[Any], Any]) -> None:
    """Rewrite a JSON file through ``edit`` (which may return the new text itself)."""
    path.write_text(_dumps(edit(json.loads(path.read_text()))))


def _edit_rows(path: Path, edit: Callable[[list[str]], list[str]]) -> None:
    path.write_text("\n".join(edit(path.read_text().splitlines())) + "\n")


def _row(edit: Callable[[dict[str, Any]], Any]) -> Callable[[Path], None]:
    """Change the first row of results.jsonl."""

    def apply(grid: Path) -> None:
        def lines(rows: list[str]) -> list[str]:
            return [_dumps(edit(json.loads(rows[0]))), *rows[1:]]

        _edit_rows(grid / "results.jsonl", lines)

    return apply


def _dumps(value: Any) -> str:
    return value if isinstance(value, str) else json.dumps(value)


def _final(text_or_edit: str | Callable[[dict[str, Any]], Any]) -> Callable[[Path], None]:
    """Replace seed0's final.json by text, or by an edit of it."""

    def apply(grid: Path) -> None:
        path = grid / SEED0 / "final.json"
        if isinstance(text_or_edit, str):
            path.write_text(text_or_edit)
        else:
            edit_json(path, text_or_edit)

    return apply


def set_path(d: dict[str, Any], dotted: str, value: Any) -> dict[str, Any]:
    *parents, last = dotted.split(".")
    node = d
    for key in parents:
        node = node[key]
    node[last] = value
    return d


def _write(rel: str, data: str | bytes) -> Callable[[Path], None]:
    def apply(grid: Path) -> None:
        path = grid / rel
        if isinstance(data, bytes):
            path.write_bytes(data)
        else:
            path.write_text(data)

    return apply


def _truncate(rel: str, keep: int = -40) -> Callable[[Path], None]:
    def apply(grid: Path) -> None:
        data = (grid / rel).read_bytes()
        (grid / rel).write_bytes(data[:keep])

    return apply


def as_dir(rel: str) -> Callable[[Path], None]:
    """A folder where a file is expected (what an unreadable file is to a reader)."""

    def apply(grid: Path) -> None:
        (grid / rel).unlink()
        (grid / rel).mkdir()
        (grid / rel / "inside").write_text("x")

    return apply


def _seed_folder(name: str) -> Callable[[Path], None]:
    """A copy of seed1's folder under another name."""

    def apply(grid: Path) -> None:
        shutil.copytree(grid / "CartPole-v1/bco/seed1", grid / "CartPole-v1/bco" / name)

    return apply


def _rename_method(name: str) -> Callable[[Path], None]:
    def apply(grid: Path) -> None:
        (grid / "CartPole-v1" / "bco").rename(grid / "CartPole-v1" / name)

    return apply


def _log(edit: Callable[[dict[str, Any]], Any]) -> Callable[[Path], None]:
    def apply(grid: Path) -> None:
        _edit_rows(grid / "bench_log.jsonl", lambda rows: [_dumps(edit(json.loads(rows[0]))),
                                                            *rows[1:]])  # fmt: skip

    return apply


#: name -> (mutation of the grid, text the report must show when it runs (None: none
#: needed), finished runs it may count, quick)
REPORT_CASES: dict[str, tuple[Callable[[Path], object], tuple[str, ...] | None, int, bool]] = {
    "results.jsonl truncated": (_truncate("results.jsonl"), ("results.jsonl",), 2, True),
    "results.jsonl a line of garbage": (
        lambda g: _edit_rows(g / "results.jsonl", lambda r: [*r, "{not json"]),
        ("results.jsonl",), 2, False),
    "results.jsonl row without env": (_row(lambda r: {k: v for k, v in r.items() if k != "env"}),
                                      ("results.jsonl",), 2, False),
    "results.jsonl row is a list": (_row(lambda r: [r]), ("results.jsonl",), 2, False),
    "results.jsonl row is null": (_row(lambda r: None), ("results.jsonl",), 2, False),
    # the first row's seed, whichever cell finished first (its seed is 0 or 1)
    "results.jsonl seed 1e400": (_row(lambda r: json.dumps({**r, "seed": -7}).replace(
        '"seed": -7', '"seed": 1e400')), ("results.jsonl",), 2, False),
    "results.jsonl seed 10**400": (_row(lambda r: json.dumps({**r, "seed": -7}).replace(
        '"seed": -7', '"seed": 1' + "0" * 400)), ("results.jsonl",), 2, False),
    "results.jsonl wall_s NaN": (_row(lambda r: {**r, "wall_s": math.nan}),
                                 ("results.jsonl",), 2, False),
    "results.jsonl final is a string": (_row(lambda r: {**r, "final": "x"}),
                                        ("results.jsonl",), 2, False),
    "results.jsonl status 123": (_row(lambda r: {**r, "status": 123}), ("results.jsonl",), 2,
                                 False),
    "results.jsonl deeply nested line": (
        lambda g: _edit_rows(g / "results.jsonl", lambda r: [*r, NESTED]),
        ("results.jsonl",), 2, False),
    "results.jsonl not UTF-8": (
        lambda g: (g / "results.jsonl").write_bytes((g / "results.jsonl").read_bytes()
                                                    + b"\xff\xfe\n"),
        ("results.jsonl",), 2, False),
    "results.jsonl empty": (_write("results.jsonl", ""), None, 2, False),
    "results.jsonl is a folder": (as_dir("results.jsonl"), ("results.jsonl",), 2, False),
    "results.jsonl host with control characters": (_row(lambda r: {**r, "host": FORGED}),
                                                   None, 2, False),
    "final.json truncated": (_truncate(f"{SEED0}/final.json"), ("seed0",), 1, False),
    "final.json {}": (_final("{}"), ("seed0",), 1, True),
    "final.json []": (_final("[]"), ("seed0",), 1, False),
    "final.json null": (_final("null"), ("seed0",), 1, False),
    "final.json NaN results": (_final(lambda f: set_path(set_path(f, "episodes.aer", math.nan),
                                                     "episodes.performance", math.nan)),
                               ("seed0",), 1, True),
    "final.json Infinity results": (
        _final(lambda f: set_path(set_path(f, "episodes.aer", math.inf), "episodes.performance",
                              math.inf)), ("seed0",), 1, False),
    "final.json -Infinity in episode returns": (
        _final(lambda f: set_path(f, "episodes.episode_returns", [-math.inf, 1.0, 2.0])),
        ("seed0",), 1, False),
    "final.json 1e999": (
        _final(lambda f: json.dumps(f).replace('"aer": ', '"aer": 1e999, "x": ', 1)),
        ("seed0",), 1, False),
    "final.json episodes 10**400": (
        _final(lambda f: json.dumps(f).replace('"episodes": 3', '"episodes": 1' + "0" * 400)),
        ("seed0",), 1, False),
    "final.json performance a string": (_final(lambda f: set_path(f, "episodes.performance", "hi")),
                                        ("seed0",), 1, False),
    "final.json aer true": (_final(lambda f: set_path(f, "episodes.aer", True)), ("seed0",), 1,
                            False),
    "final.json empty episode lists": (
        _final(lambda f: set_path(set_path(f, "episodes.episode_returns", []),
                              "episodes.episode_performance", [])), ("seed0",), 1, False),
    "final.json without episodes": (_final(lambda f: {k: v for k, v in f.items()
                                                      if k != "episodes"}), ("seed0",), 1,
                                    False),
    "final.json episodes is a list": (_final(lambda f: set_path(f, "episodes", [1, 2])),
                                      ("seed0",), 1, False),
    "final.json interactions 1e400": (
        _final(lambda f: json.dumps(f).replace('"pre_demonstration": ',
                                               '"pre_demonstration": 1e400, "x": ')),
        ("seed0",), 1, False),
    "final.json deeply nested": (_final(NESTED), ("seed0",), 1, False),
    "final.json not UTF-8": (_write(f"{SEED0}/final.json", b'{"env": "\xff"}'), ("seed0",), 1,
                             False),
    "final.json is a folder": (as_dir(f"{SEED0}/final.json"), ("seed0",), 1, False),
    "final.json status with control characters": (_final(lambda f: {**f, "status": FORGED}),
                                                  ("seed0",), 1, False),
    "metrics.jsonl truncated": (_truncate(f"{SEED0}/metrics.jsonl", 30), None, 2, False),
    "metrics.jsonl NaN": (_write(f"{SEED0}/metrics.jsonl",
                                 '{"iteration": 0, "eval": {"performance": NaN}}\n'),
                          None, 2, False),
    "metrics.jsonl a list per line": (_write(f"{SEED0}/metrics.jsonl", "[1]\n[2]\n"), None, 2,
                                      False),
    "metrics.jsonl is a folder": (as_dir(f"{SEED0}/metrics.jsonl"), None, 2, False),
    "bench_log.jsonl truncated": (_truncate("bench_log.jsonl"), None, 2, False),
    "bench_log.jsonl a list": (_log(lambda r: [r]), None, 2, False),
    "bench_log.jsonl wall_s NaN": (_log(lambda r: {**r, "wall_s": math.nan}), None, 2, False),
    "bench_log.jsonl without wall_s": (_log(lambda r: {k: v for k, v in r.items()
                                                       if k != "wall_s"}), None, 2, False),
    "bench_log.jsonl backend with control characters": (
        _log(lambda r: {**r, "backend": FORGED}), None, 2, False),
    "a folder seed²": (_seed_folder("seed²"), ("seed²", "seed\\xb2", "seed\\u00b2"), 2, False),
    "a folder seed٣": (_seed_folder("seed٣"), ("seed٣", "seed\\u0663"), 2, True),
    "a folder seed00 (a second seed 0)": (_seed_folder("seed00"), None, 2, False),
    "a folder seed99999999999999999999": (_seed_folder("seed99999999999999999999"), None, 3,
                                          False),
    "a method folder with control characters": (_rename_method("bco\x1b[2J\nerror: forged"),
                                                None, 2, False),
    "a seed folder that links to itself": (
        lambda g: (g / "CartPole-v1/bco/seed7").symlink_to("seed7"), None, 2, False),
}  # fmt: skip


def _csv_problem(path: Path, good: int) -> str | None:
    """A number of the report's csv that is not finite, or a cell counting more runs than
    ``good``."""
    try:
        rows = list(csv.DictReader(io.StringIO(path.read_text())))
    except (OSError, UnicodeDecodeError) as exc:
        return f"results.csv unreadable ({exc})"
    for row in rows:
        for key in ("mean", "ci_low", "ci_high", "iqm"):
            value = (row.get(key) or "").strip()
            try:
                number = float(value) if value else 0.0
            except ValueError:
                continue
            if not math.isfinite(number):
                return f"results.csv holds {key}={value} ({row.get('env')}, {row.get('metric')})"
        if (row.get("seeds") or "0").isdigit() and int(row["seeds"]) > good:
            return f"results.csv counts {row['seeds']} runs of {row.get('env')}/" \
                   f"{row.get('method')} (only {good} are sound)"  # fmt: skip
    return None


def report_case(ctx: Ctx, name: str, mutate: Callable[[Path], object],
                hint: tuple[str, ...] | None, good: int) -> Outcome:  # fmt: skip
    base = ctx.scratch(name)
    grid = copy_grid(ctx, base / "grid")
    mutate(grid)
    out = base / "report"
    res = ctx.abco("report", str(grid), "--out", str(out), timeout=90)
    shown = res.out + res.err + _text(out / "report.md")
    if "\x1b" in shown or "\nerror: forged" in shown:
        return fail("silent", "a record's control characters were printed raw")
    if res.rc != 0 or res.timed_out or TRACEBACK.search(res.err):
        return refused(res)
    if hint is not None and not any(h in shown for h in hint):
        return fail("silent", f"the report ran without naming {hint[0]}")
    problem = _csv_problem(out / "results.csv", good) if (out / "results.csv").exists() else None
    return fail("silent", problem) if problem else ok("named and skipped" if hint else "ran")


def _text(path: Path) -> str:
    try:
        return path.read_text(errors="replace")
    except OSError:
        return ""


def cases() -> list[Case]:
    """``abco report`` on each damaged grid."""
    return [Case(FAMILY, f"report: {name}", partial(report_case, name=name, mutate=mutate,
                                                     hint=hint, good=good), quick=quick)
            for name, (mutate, hint, good, quick) in REPORT_CASES.items()]  # fmt: skip
