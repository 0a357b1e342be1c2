"""Family 6, part two: crafted run folders.

``abco train`` resuming, ``abco play`` and ``abco_train.load_policy`` on copies of a finished
tiny run with a crafted ``final.json``, ``config.json``, ``metrics.jsonl`` or checkpoint (the
checkpoint edited as plain data: skipped where its format is not). Held: one ``error:`` line
that names the crafted file (``load_policy``: one of abco's own exceptions), and the folder
unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from attacks.core import (
    Case,
    Ctx,
    Outcome,
    Result,
    fail,
    kept,
    ok,
    probe_answer,
    refused,
    skip,
    snapshot,
)
from attacks.fixtures import copy_run, train_flags
from attacks.records import FAMILY, NESTED, as_dir, edit_json, set_path


def _run_file(name: str, data: str | bytes | Callable[[Path], object]) -> Callable[[Path], None]:
    def apply(run: Path) -> None:
        if callable(data):
            data(run)
        elif isinstance(data, bytes):
            (run / name).write_bytes(data)
        else:
            (run / name).write_text(data)

    return apply


def _checkpoint(edit: Callable[[dict[str, Any]], Any]) -> Callable[[Path], None]:
    """Edit the checkpoint as plain data (read with ``weights_only=True``, written back with
    ``torch.save``); raises :class:`LookupError` where the format is not plain data."""

    def apply(run: Path) -> None:
        import torch

        try:
            state = torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=True)
        except Exception as exc:
            raise LookupError(f"the checkpoint is not plain data ({type(exc).__name__})") from exc
        torch.save(edit(state), run / "checkpoint.pt")

    return apply


def _reshape_tensors(state: Any) -> Any:
    """Every tensor of the method's state, one row longer (a size mismatch)."""
    import torch

    if isinstance(state, torch.Tensor):
        return torch.zeros((state.shape[0] + 1, *state.shape[1:])) if state.dim() else state
    if isinstance(state, dict):
        return {k: _reshape_tensors(v) for k, v in state.items()}
    if isinstance(state, list):
        return [_reshape_tensors(v) for v in state]
    return state


def _without(key: str) -> Callable[[dict[str, Any]], dict[str, Any]]:
    return lambda s: {k: v for k, v in s.items() if k != key}


def _play(ctx: Ctx, run: Path, base: Path) -> Result:
    return ctx.abco("play", str(run), "--episodes", "0", "--quiet", "--out",
                    str(base / "p.gif"), timeout=120)  # fmt: skip


def _resume(ctx: Ctx, run: Path, base: Path) -> Result:
    return ctx.abco("train", *train_flags(ctx), "--run-dir", str(run), timeout=120)


_LOAD_POLICY = """
import json, sys, abco_train
try:
    abco_train.load_policy(sys.argv[1])
except Exception as exc:
    print(json.dumps({"error": type(exc).__name__, "module": type(exc).__module__,
                      "message": str(exc)[:300]}))
else:
    print(json.dumps({"loaded": True}))
"""


def api_refused(res: Result) -> Outcome:
    """A Python call that must raise one of abco's own errors (not load, not crash with a
    KeyError or a RecursionError)."""
    failed, answer = probe_answer(res)
    if failed is not None:
        return failed
    what = f"{answer['error']}: {answer['message'][:160]}"
    if not str(answer.get("module", "")).startswith("abco"):
        return fail("traceback", f"not an abco error: {what}")
    return ok(what)


def _load_policy(ctx: Ctx, run: Path, base: Path) -> Result:
    return ctx.python(_LOAD_POLICY, str(run), timeout=120)


USES = {"play": _play, "resume": _resume, "load_policy": _load_policy}

#: name -> (crafting of a copy of the trained run, keep final.json, uses, quick)
RUN_CASES: dict[str, tuple[Callable[[Path], None], bool, tuple[str, ...], bool]] = {
    "final.json []": (_run_file("final.json", "[]"), True, ("resume",), False),
    "final.json {}": (_run_file("final.json", "{}"), True, ("resume",), True),
    "final.json null": (_run_file("final.json", "null"), True, ("resume",), False),
    "final.json deeply nested": (_run_file("final.json", NESTED), True, ("resume",), False),
    "final.json episodes a string": (_run_file("final.json", '{"status": "ok", "episodes": "x"}'),
                                     True, ("resume",), False),
    "final.json status ok only": (_run_file("final.json", '{"status": "ok"}'), True, ("resume",),
                                  False),
    "final.json NaN results": (_run_file("final.json", lambda r: edit_json(
        r / "final.json", lambda f: set_path(f, "episodes.aer", math.nan))), True, ("resume",),
        False),
    "final.json truncated": (_run_file("final.json", lambda r: (r / "final.json").write_bytes(
        (r / "final.json").read_bytes()[:-30])), True, ("resume",), False),
    "final.json is a folder": (as_dir("final.json"), True, ("resume",), False),
    "config.json []": (_run_file("config.json", "[]"), False, ("resume", "play", "load_policy"),
                       False),
    "config.json {}": (_run_file("config.json", "{}"), False, ("play",), False),
    "config.json truncated": (_run_file("config.json", lambda r: (r / "config.json").write_bytes(
        (r / "config.json").read_bytes()[:-50])), False, ("resume", "play"), False),
    "config.json deeply nested": (_run_file("config.json", NESTED), False, ("resume", "play"),
                                  False),
    "config.json method 5": (_run_file("config.json", lambda r: edit_json(
        r / "config.json", lambda c: {**c, "method": 5})), False, ("play",), False),
    "config.json seed 'x'": (_run_file("config.json", lambda r: edit_json(
        r / "config.json", lambda c: {**c, "seed": "x"})), False, ("play", "resume"), False),
    "config.json of another env (sizes differ)": (_run_file("config.json", lambda r: edit_json(
        r / "config.json", lambda c: {**c, "env": "Acrobot-v1"})), False, ("play",), True),
    "config.json with attention on (networks differ)": (
        _run_file("config.json", lambda r: edit_json(
            r / "config.json", lambda c: {**c, "attention": True})),
        False, ("play", "load_policy"), False),
    "config.json of another method": (_run_file("config.json", lambda r: edit_json(
        r / "config.json", lambda c: {**c, "method": "ilpo"})), False, ("play",), False),
    "metrics.jsonl truncated": (_run_file("metrics.jsonl", lambda r: (r / "metrics.jsonl")
                                          .write_bytes((r / "metrics.jsonl").read_bytes()[:-30])),
                                False, ("resume",), False),
    "metrics.jsonl garbage": (_run_file("metrics.jsonl", "not json\n"), False, ("resume",), False),
    "metrics.jsonl NaN and lists": (_run_file("metrics.jsonl", '[1]\n{"iteration": NaN}\n'),
                                    False, ("resume",), False),
    "checkpoint.pt truncated": (_run_file("checkpoint.pt", lambda r: (r / "checkpoint.pt")
                                          .write_bytes((r / "checkpoint.pt").read_bytes()[:200])),
                                False, ("play", "resume"), False),
    "checkpoint.pt empty": (_run_file("checkpoint.pt", b""), False, ("play", "resume"), False),
    "checkpoint.pt random bytes": (_run_file("checkpoint.pt", bytes(range(256)) * 8), False,
                                   ("play",), False),
    "checkpoint.pt is a folder": (as_dir("checkpoint.pt"), False, ("play", "resume"), False),
    "checkpoint iteration -100": (_checkpoint(lambda s: {**s, "iteration": -100}), False,
                                  ("resume", "play"), True),
    "checkpoint iteration 'x'": (_checkpoint(lambda s: {**s, "iteration": "x"}), False,
                                 ("resume",), False),
    "checkpoint iteration 10**30": (_checkpoint(lambda s: {**s, "iteration": 10**30}), False,
                                    ("resume",), False),
    "checkpoint without iteration": (_checkpoint(_without("iteration")), False,
                                     ("play", "resume"), False),
    "checkpoint method state {}": (_checkpoint(lambda s: {**s, "method": {}}), False,
                                   ("play",), False),
    "checkpoint tensors of other sizes": (_checkpoint(lambda s: {
        **s, "method": _reshape_tensors(s.get("method"))}), False, ("play", "resume"), False),
    "checkpoint without config": (_checkpoint(_without("config")), False, ("resume",), False),
}  # fmt: skip


#: What a kill during a write leaves (a last line cut short): resuming past it is fine.
#: Case -> the file resuming rewrites without the cut line.
RESUMABLE = {"metrics.jsonl truncated": "metrics.jsonl"}


def run_case(ctx: Ctx, name: str, craft: Callable[[Path], None], final: bool, use: str
             ) -> Outcome:  # fmt: skip
    base = ctx.scratch(f"{name} {use}")
    run = copy_run(ctx, base / "run", final=final)
    try:
        craft(run)
    except LookupError as exc:
        return skip(str(exc))
    before = snapshot(run)
    res = USES[use](ctx, run, base)
    named = name.split()[0].replace("checkpoint", "checkpoint.pt").replace(".pt.pt", ".pt")
    # a config that does not fit the checkpoint or the data: naming either side is clear
    also = ("checkpoint.pt", ".hdf5") if named == "config.json" else ()
    if use == "resume" and name in RESUMABLE and res.rc == 0 and not res.err.strip():
        rest = {k: v for k, v in before.items() if k != RESUMABLE[name]}  # rewritten whole
        return kept(rest, run, ok("resumed past it, as after a kill"))
    outcome = api_refused(res) if use == "load_policy" else \
        refused(res, mention=(named, *also))  # fmt: skip
    return kept(before, run, outcome)


def cases() -> list[Case]:
    """Each crafted run folder with each of its uses."""
    out = []
    for name, (craft, final, uses, quick) in RUN_CASES.items():
        for i, use in enumerate(uses):
            out.append(Case(FAMILY, f"{use}: {name}", partial(run_case, name=name, craft=craft,
                                                              final=final, use=use),
                            quick=quick and i == 0))  # fmt: skip
    return out
