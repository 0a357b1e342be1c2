"""Family 1: code from checkpoints.

A run folder's ``checkpoint.pt`` is replaced by a pickle payload (its ``__reduce__`` creates a
marker file, or runs ``touch`` through ``os.system``) in five forms, and the folder is used
five ways: ``abco_train.load_policy``, ``abco play``, resuming ``abco train`` with the folder's
config, ``abco train`` with another config on it, and (two of the forms) ``abco bench``
resuming it as a cell.
An old checkpoint without a payload (numpy inside, as ABCO's and ILPO's states held) is used
three ways. Held: the marker never appears, and each command ends with one ``error:`` line;
where the checkpoint is what is refused, that line names ``abco convert-checkpoint``.
"""

from __future__ import annotations

import json
import os
import pickle
import shlex
import shutil
import threading
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from attacks.core import Case, Ctx, Outcome, Result, fail, kept, ok, probe_answer, refused, snapshot
from attacks.fixtures import bench_flags, copy_run, train_flags

FAMILY = "checkpoints"
CONVERT = "convert-checkpoint"
_torch_lock = threading.Lock()


class OpenPayload:
    """Unpickled, it creates ``marker`` (``open(marker, "w")``)."""

    def __init__(self, marker: str) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, ...]:
        return (open, (self.marker, "w"))


class ShellPayload:
    """Unpickled, it runs ``touch marker`` in a shell."""

    def __init__(self, marker: str) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, ...]:
        return (os.system, (f"touch {shlex.quote(self.marker)}",))


def _legacy(run: Path, method_state: Any, **extra: Any) -> dict[str, Any]:
    """A checkpoint as abco wrote them before: one pickled dict."""
    import torch

    return {"iteration": 0, "method": method_state, "interactions": {},
            "torch_rng": torch.get_rng_state(),
            "config": json.loads((run / "config.json").read_text()), "cuda_rng": None,
            **extra}  # fmt: skip


def _torch_save(obj: Any, path: Path, *, legacy_format: bool = False) -> None:
    import torch

    with _torch_lock:
        torch.save(obj, path, _use_new_zipfile_serialization=not legacy_format)


#: name -> writer(run folder, checkpoint path, marker)
PAYLOADS: dict[str, Callable[[Path, Path, str], object]] = {
    "zip, payload in the method state": lambda run, ckpt, marker: _torch_save(
        _legacy(run, {"policy": OpenPayload(marker)}), ckpt),
    "zip, os.system payload as the whole file": lambda run, ckpt, marker: _torch_save(
        ShellPayload(marker), ckpt),
    "raw pickle named checkpoint.pt": lambda run, ckpt, marker: ckpt.write_bytes(
        pickle.dumps(_legacy(run, {"policy": OpenPayload(marker)}), protocol=4)),
    "torch legacy tar format": lambda run, ckpt, marker: _torch_save(
        _legacy(run, {"policy": OpenPayload(marker)}), ckpt, legacy_format=True),
    "zip, payload in the config": lambda run, ckpt, marker: _torch_save(
        _legacy(run, {}, config={"env": OpenPayload(marker)}), ckpt),
}  # fmt: skip


def _old_checkpoint(run: Path, ckpt: Path, marker: str) -> None:
    """An old-format checkpoint without a payload: numpy arrays in the method's state."""
    import numpy as np

    del marker
    _torch_save(_legacy(run, {"alpha_counts": np.zeros(4), "rng": np.random.default_rng(0)}),
                ckpt)  # fmt: skip


def _folder(ctx: Ctx, name: str, write: Callable[[Path, Path, str], object], *, final: bool
            ) -> tuple[Path, Path]:  # fmt: skip
    """A copy of the trained run with the crafted checkpoint; (folder, marker)."""
    base = ctx.scratch(name)
    run = copy_run(ctx, base / "run", final=final)
    marker = base / "MARKER-code-ran"
    write(run, run / "checkpoint.pt", str(marker))
    return run, marker


def _code_ran(marker: Path) -> Outcome | None:
    return fail("code", f"the payload ran: {marker.name} exists") if marker.exists() else None


# -- the ways a folder is used --------------------------------------------------------------

_LOAD_POLICY = """
import json, sys
import abco_train
try:
    abco_train.load_policy(sys.argv[1])
except Exception as exc:
    print(json.dumps({"error": type(exc).__name__, "message": str(exc)}))
else:
    print(json.dumps({"loaded": True}))
"""


def _load_policy(ctx: Ctx, name: str, write: Callable[..., object], mention: bool) -> Outcome:
    run, marker = _folder(ctx, name, write, final=True)
    res = ctx.python(_LOAD_POLICY, str(run))
    return _code_ran(marker) or _api_refused(res, CONVERT if mention else None)


def _api_refused(res: Result, mention: str | None) -> Outcome:
    """A Python call that must raise one clear exception (not load, not crash)."""
    failed, answer = probe_answer(res)
    if failed is not None:
        return failed
    message = str(answer.get("message", ""))
    if mention and mention not in message:
        return fail("traceback", f"{answer.get('error')} does not name {mention}: "
                    f"{message[:180]}")  # fmt: skip
    return ok(f"{answer.get('error')}: {message[:160]}")


def _play(ctx: Ctx, name: str, write: Callable[..., object], mention: bool) -> Outcome:
    run, marker = _folder(ctx, name, write, final=True)
    before = snapshot(run)
    res = ctx.abco("play", str(run), "--episodes", "0", "--quiet",
                   "--out", str(run.parent / "play.gif"))  # fmt: skip
    outcome = _code_ran(marker) or refused(res, mention=CONVERT if mention else None)
    return kept(before, run, outcome)


def _resume(ctx: Ctx, name: str, write: Callable[..., object], mention: bool) -> Outcome:
    run, marker = _folder(ctx, name, write, final=False)
    before = snapshot(run)
    res = ctx.abco("train", *train_flags(ctx), "--run-dir", str(run))
    outcome = _code_ran(marker) or refused(res, mention=CONVERT if mention else None)
    return kept(before, run, outcome)


def _other_config(ctx: Ctx, name: str, write: Callable[..., object], mention: bool) -> Outcome:
    del mention  # refusing the folder for its config is as good as refusing the checkpoint
    run, marker = _folder(ctx, name, write, final=True)
    before = snapshot(run)
    res = ctx.abco("train", *train_flags(ctx, method="bc"), "--run-dir", str(run))
    return kept(before, run, _code_ran(marker) or refused(res))


def _bench_cell(ctx: Ctx, name: str, write: Callable[..., object], mention: bool) -> Outcome:
    base = ctx.scratch(name)
    grid = base / "grid"
    cell = grid / "CartPole-v1" / "bco" / "seed0"
    cell.mkdir(parents=True)
    shutil.copy(ctx.fixture("grid") / "CartPole-v1" / "bco" / "seed0" / "config.json", cell)
    marker = base / "MARKER-code-ran"
    write(cell, cell / "checkpoint.pt", str(marker))
    res = ctx.abco("bench", "--envs", "CartPole-v1", "--methods", "bco", "--seeds", "0",
                   "--out", str(grid), "--jobs", "1", *bench_flags(ctx))  # fmt: skip
    found = _code_ran(marker)
    if found:
        return found
    if res.timed_out:
        return fail("hang", f"still running after {res.timeout:.0f} s")
    if res.rc == 0:
        return fail("silent", "the grid ran the cell (exit 0)")
    if res.rc not in (1, 2) or "Traceback" in res.err:
        return fail("traceback", res.summary())
    if mention and CONVERT not in res.out + res.err:
        return fail("traceback", f"nothing names {CONVERT}: {res.summary()}")
    return ok(res.summary())


USES = {
    "load_policy": _load_policy,
    "abco play": _play,
    "abco train resume": _resume,
    "abco train, another config": _other_config,
    "abco bench cell resume": _bench_cell,
}
BENCHED = ("zip, payload in the method state", "raw pickle named checkpoint.pt")
QUICK = {("zip, payload in the method state", "load_policy"),
         ("raw pickle named checkpoint.pt", "abco train resume"),
         ("zip, os.system payload as the whole file", "abco play")}  # fmt: skip


def cases() -> list[Case]:
    """Five payloads times four uses (two of them in a bench cell too), and the old
    checkpoint three ways."""
    out = []
    for payload, write in PAYLOADS.items():
        for use, attack in USES.items():
            if use == "abco bench cell resume" and payload not in BENCHED:
                continue  # a cell loads its checkpoint as train does: two forms suffice
            name = f"{payload} / {use}"
            out.append(Case(FAMILY, name, partial(attack, name=name, write=write, mention=True),
                            quick=(payload, use) in QUICK))  # fmt: skip
    for use in ("load_policy", "abco play", "abco train resume"):
        name = f"old checkpoint (numpy inside) / {use}"
        out.append(Case(FAMILY, name, partial(USES[use], name=name, write=_old_checkpoint,
                                              mention=True)))  # fmt: skip
    return out
