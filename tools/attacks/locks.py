"""Family 3: one writer at a time.

Two ``abco bench`` into one ``--out`` started together (other cells; the same cells), and two
``abco train`` on one run folder started together (another config; the same config). Held:
no row lost (every cell a successful bench ran, and every finished cell folder, has its row
in ``results.jsonl``, and every successful session its line in ``bench_log.jsonl``); a run
folder's ``config.json``, ``final.json`` and checkpoint are of one config, and its
``metrics.jsonl`` has each iteration once; a writer that does not run is refused with one
``error:`` line.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from attacks.core import TRACEBACK, Case, Ctx, Outcome, Result, fail, ok, refused
from attacks.fixtures import TINY, bench_flags, train_flags

FAMILY = "locks"


def together(*calls: Callable[[], Result]) -> list[Result]:
    """Run the calls at the same moment (one thread each); their results in order."""
    results: list[Result | None] = [None] * len(calls)
    start = threading.Barrier(len(calls))

    def one(i: int) -> None:
        start.wait()
        results[i] = calls[i]()

    threads = [threading.Thread(target=one, args=(i,)) for i in range(len(calls))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return [r for r in results if r is not None]


def _read_jsonl(path: Path) -> list[Any]:
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text(errors="replace").splitlines():
        try:
            rows.append(json.loads(line))
        except ValueError:
            rows.append({"unreadable": line[:80]})
    return rows


def _cell_failed(res: Result) -> bool:
    """``abco bench`` that ran and reported its cell as failed in one line (exit 1): how a
    bench tells a cell it could not run, e.g. one another writer holds."""
    return res.rc == 1 and not TRACEBACK.search(res.err) and \
        sum("FAILED" in line for line in res.out.splitlines()) == 1  # fmt: skip


def _losers(results: list[Result]) -> Outcome | None:
    """A failure for any writer that neither ran (exit 0) nor was refused in one line;
    ``None`` when each did one or the other and at least one ran."""
    for i, res in enumerate(results):
        if res.rc == 0 or _cell_failed(res):
            continue
        verdict = refused(res)
        if verdict.failed:
            return Outcome(verdict.verdict, f"writer {i + 1}: {verdict.detail}")
    if all(r.rc != 0 for r in results):
        return fail("silent", "every writer was refused: "
                    + " / ".join(r.summary() for r in results))  # fmt: skip
    return None


def _bench(ctx: Ctx, out: Path, seeds: str) -> Result:
    return ctx.abco("bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds", seeds,
                    "--out", str(out), "--jobs", "1", *bench_flags(ctx), timeout=300)  # fmt: skip


def _rows_kept(out: Path, results: list[Result], seeds: list[str]) -> Outcome | None:
    rows = {(r.get("env"), r.get("method"), r.get("seed")): r
            for r in _read_jsonl(out / "results.jsonl") if isinstance(r, dict)}  # fmt: skip
    log = _read_jsonl(out / "bench_log.jsonl")
    for res, text in zip(results, seeds):
        if res.rc != 0:
            continue
        first, _, last = text.partition("-")
        for seed in range(int(first), int(last or first) + 1):
            row = rows.get(("CartPole-v1", "bco", seed))
            if row is None or row.get("status") != "done":
                return fail("lost", f"results.jsonl has no done row of seed {seed} "
                            f"(its bench exited 0)")  # fmt: skip
    for text in set(seeds):
        needed = sum(r.rc == 0 and s == text for r, s in zip(results, seeds))
        have = sum(isinstance(x, dict) and text in (x.get("argv") or []) for x in log)
        if have < needed:
            return fail("lost", f"bench_log.jsonl holds {have} of the {needed} sessions of "
                        f"seeds {text} that exited 0")  # fmt: skip
    for final in out.glob("*/*/seed*/final.json"):
        seed = int(final.parent.name[4:])
        if ("CartPole-v1", "bco", seed) not in rows:
            return fail("lost", f"{final.parent.name} finished but has no row")
    return None


def two_benches(ctx: Ctx, seeds: tuple[str, str]) -> Outcome:
    out = ctx.scratch(f"two benches {seeds}") / "grid"
    results = together(lambda: _bench(ctx, out, seeds[0]), lambda: _bench(ctx, out, seeds[1]))
    if any(r.timed_out for r in results):
        return fail("hang", "a bench was still running after 300 s")
    found = _losers(results) or _rows_kept(out, results, list(seeds))
    if found:
        return found
    for cell in out.glob("*/*/seed*"):
        mixed = _mixed(cell)
        if mixed:
            return fail("mixed", f"{cell.name}: {mixed}")
    return ok(" / ".join(r.summary() for r in results))


def _checkpoint_config(path: Path) -> dict[str, Any] | None:
    """The config a checkpoint records, read without unpickling anything (``None`` where
    its format is not a torch file of plain data)."""
    try:
        import torch

        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:
        return None
    config = state.get("config") if isinstance(state, dict) else None
    return config if isinstance(config, dict) else None


def _mixed(run: Path) -> str | None:
    """What disagrees in a run folder: config.json, final.json, the checkpoint, metrics."""
    try:
        config = json.loads((run / "config.json").read_text())
    except (OSError, ValueError):
        return None
    method = config.get("method")
    final_path = run / "final.json"
    if final_path.is_file():
        try:
            final = json.loads(final_path.read_text())
        except ValueError:
            return "final.json is unreadable"
        if isinstance(final, dict) and final.get("method") not in (None, method):
            return f"config.json of {method}, final.json of {final.get('method')}"
    ckpt = _checkpoint_config(run / "checkpoint.pt") if (run / "checkpoint.pt").exists() else None
    if ckpt is not None and ckpt.get("method") != method:
        return f"config.json of {method}, checkpoint of {ckpt.get('method')}"
    iterations = [r.get("iteration") for r in _read_jsonl(run / "metrics.jsonl")
                  if isinstance(r, dict)]  # fmt: skip
    if len(iterations) != len(set(iterations)):
        return f"metrics.jsonl repeats iterations: {iterations}"
    return None


def two_trains(ctx: Ctx, methods: tuple[str, str]) -> Outcome:
    run = ctx.scratch(f"two trains {methods}") / "run"
    longer = ["--iterations", "3"]  # a few seconds of overlap for the two writers

    def train(method: str) -> Callable[[], Result]:
        flags = [*train_flags(ctx, method=method), *longer]
        return lambda: ctx.abco("train", *flags, "--run-dir", str(run), timeout=240)

    results = together(train(methods[0]), train(methods[1]))
    if any(r.timed_out for r in results):
        return fail("hang", "a train was still running after 240 s")
    found = _losers(results)
    if found:
        return found
    if methods[0] != methods[1] and all(r.rc == 0 for r in results):
        return fail("mixed", f"both writers of other configs ran to the end in {run.name}")
    mixed = _mixed(run)
    if mixed:
        return fail("mixed", mixed)
    if not (run / "final.json").is_file():
        return fail("lost", "a train exited 0 but the folder has no final.json")
    return ok(" / ".join(r.summary() for r in results))


def bench_and_train(ctx: Ctx) -> Outcome:
    """``abco train`` into a cell folder while ``abco bench`` runs that cell."""
    out = ctx.scratch("bench and train") / "grid"
    cell = out / "CartPole-v1" / "bco" / "seed0"
    data = ctx.fixture("data")
    flags = ["--env", "CartPole-v1", "--method", "bco", "--seed", "0", "--expert-data",
             data["expert"], "--pre-data", data["pre"], *TINY, "--threads", "1", "--quiet",
             "--run-dir", str(cell)]  # fmt: skip
    results = together(lambda: _bench(ctx, out, "0"),
                       lambda: ctx.abco("train", *flags, timeout=240))  # fmt: skip
    if any(r.timed_out for r in results):
        return fail("hang", "still running after 240 s")
    found = _losers(results) or _rows_kept(out, results[:1], ["0"])
    if found:
        return found
    mixed = _mixed(cell)
    return fail("mixed", mixed) if mixed else ok(" / ".join(r.summary() for r in results))


def cases() -> list[Case]:
    """Two benches (other cells, same cells), two trains (other config, same), and a train
    inside a running bench's cell."""
    return [
        Case(FAMILY, "two benches, one --out, other cells",
             lambda ctx: two_benches(ctx, ("0-1", "2-3")), quick=True),
        Case(FAMILY, "two benches, one --out, the same cells",
             lambda ctx: two_benches(ctx, ("0-1", "0-1"))),
        Case(FAMILY, "two trains, one run folder, other configs",
             lambda ctx: two_trains(ctx, ("bco", "bc")), quick=True),
        Case(FAMILY, "two trains, one run folder, the same config",
             lambda ctx: two_trains(ctx, ("bco", "bco"))),
        Case(FAMILY, "train into a cell a bench is running", bench_and_train),
    ]  # fmt: skip
