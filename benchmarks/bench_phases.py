"""Where a headline cell's time goes: one cell per method on each headline task, profiled.

Each cell runs in a process of its own (as ``abco bench`` runs it: the track's settings, one
torch thread, no plots) under ``cProfile``, with a phase clock wrapped around the functions
that begin each phase. Every second of the cell belongs to exactly one phase, the innermost
one running (the IDM's minibatch preparation counts as ``pairs``, not as IDM fitting):

==============  ==============================================================================
phase           what runs
==============  ==============================================================================
data            loading and decoding the datasets (``load_training_data``), building the method
pairs           preparing the networks' inputs: pairs ``(s, s')`` and frames per minibatch
idm             fitting the IDM (ILPO: its latent model and latent policy; GAIfO: its
                discriminator)
policy          fitting the policy (ILPO: its action remapping; GAIfO: PPO, its environment
                steps included)
labels          predictions over the expert's pairs and states (labels, label accuracy)
rollouts        each iteration's evaluation runs, which are the post-demonstrations (ILPO:
                and its remapping steps)
evaluation      the final evaluation (its references apart)
references      the score's references (random walks, expert paths, fresh layouts)
records         checkpoints, metrics and ``final.json``
other           the rest (the harness between phases)
==============  ==============================================================================

It uses validation seeds only (the track's first, 100, by default) and refuses test seeds.
The ``cProfile`` statistics of each cell are written to ``OUT/<task>-<method>.prof`` for a
closer look (``python -m pstats``); the table goes to ``OUT/phases.csv``. Run it on two
checkouts to compare code versions: the functions it wraps are looked up by name, and one
that a version lacks is left out of that version's clock.

Usage::

    python benchmarks/bench_phases.py --out runs/phases                  # every task (hours)
    python benchmarks/bench_phases.py --tasks maze3x3-heldout --methods bc,abco
    python benchmarks/bench_phases.py --tiny                              # seconds: a smoke test

``--tiny`` runs two methods on CartPole with one short iteration; its figures mean nothing.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import csv
import functools
import json
import subprocess
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from importlib import import_module
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
PHASES = ("data", "pairs", "idm", "policy", "labels", "rollouts", "evaluation", "references",
          "records", "other")
METHODS = "bc,bco,bco-alpha,bco-alpha-torabi,abco,iupe,ilpo,gaifo"
#: Settings of ``--tiny``: one short iteration, a tiny evaluation (as bench_gpu.py's).
TINY = {"iterations": 0, "first_epochs_factor": 1, "idm_epochs": 1, "policy_epochs": 1,
        "eval_episodes": 2, "eval_max_steps": 10}


class PhaseClock:
    """Seconds per phase; the innermost phase entered owns the time."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.stack: list[str] = []
        self.mark = time.perf_counter()

    def _switch(self) -> None:
        now = time.perf_counter()
        self.seconds[self.stack[-1] if self.stack else "other"] += now - self.mark
        self.mark = now

    def timed(self, phase: str | Callable[[list[str]], str], fn: Callable) -> Callable:
        """``fn`` with its calls counted to ``phase`` (or to ``phase(stack)``)."""
        clock = self

        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            name = phase(clock.stack) if callable(phase) else phase
            clock._switch()
            clock.stack.append(name)
            try:
                return fn(*args, **kwargs)
            finally:
                clock._switch()
                clock.stack.pop()

        return wrapper


def _fitting(stack: list[str]) -> str:
    """A supervised fit (or prediction) inside an IDM fit belongs to it; else the policy's."""
    return "idm" if "idm" in stack else "policy"


def _labelling(stack: list[str]) -> str:
    return "idm" if "idm" in stack else "labels"


#: ``(module, attribute path, phase)``: what the clock wraps. An attribute a code version
#: lacks is skipped; ``fit``/``predict`` also time their ``inputs`` callable as ``pairs``.
WRAPPED: list[tuple[str, str, Any]] = [
    ("abco_train.harness.loop", "load_training_data", "data"),
    ("abco_train.harness.loop", "rollout", "rollouts"),
    ("abco_train.harness.loop", "final_evaluation", "evaluation"),
    ("abco_train.harness.loop", "save_checkpoint", "records"),
    ("abco_train.harness.loop", "_write_history", "records"),
    ("abco_train.harness.loop", "write_atomic", "records"),
    ("abco_data", "protocol_reference", "references"),
    ("abco_data", "layout_reference", "references"),
    ("abco_data.reference", "classic_reference", "references"),  # before abco_data's rooms
    ("abco_data.generation.reference", "classic_reference", "references"),
    ("abco_train.harness.evaluation", "fresh_set", "references"),
    ("abco_train.methods.bco.family", "BCOFamily._train_idm", "idm"),
    ("abco_train.methods.bco.family", "BCOFamily.validate_idm", "idm"),
    ("abco_train.methods.bco.family", "BCOFamily.observe", "rollouts"),
    ("abco_train.methods.ilpo.method", "ILPO._train_latent_model", "idm"),
    ("abco_train.methods.ilpo.method", "ILPO._collect", "rollouts"),
    ("abco_train.methods.ilpo.method", "ILPO._expert_statistics", "labels"),
    ("abco_train.methods.ilpo.remapping", "ActionRemapping.fit", "policy"),
    ("abco_train.methods.gaifo.method", "GAIfO.update_discriminator", "idm"),
    ("stable_baselines3", "PPO.learn", "policy"),
]
#: Functions whose ``inputs`` argument (minibatch preparation) is timed as ``pairs``.
FITTING = [("abco_train.methods.bco.fitting", "fit", _fitting),
           ("abco_train.methods.bco.fitting", "predict", _labelling)]


def install(clock: PhaseClock) -> None:
    """Wrap :data:`WRAPPED` and :data:`FITTING` (in every module that imported them)."""
    for module, path, phase in WRAPPED:
        try:
            owner: Any = import_module(module)
            *parents, name = path.split(".")
            for parent in parents:
                owner = getattr(owner, parent)
            setattr(owner, name, clock.timed(phase, getattr(owner, name)))
        except (ImportError, AttributeError):
            continue  # this code version (or install) has no such function
    for module, name, phase in FITTING:
        try:
            original = getattr(import_module(module), name)
        except (ImportError, AttributeError):
            continue

        def with_pairs(*args: Any, _fn: Callable = original, **kwargs: Any) -> Any:
            args = list(args)
            if len(args) > 2 and callable(args[2]):  # fit(net, opt, inputs, ...)
                args[2] = clock.timed("pairs", args[2])
            elif len(args) > 1 and callable(args[1]):  # predict(net, inputs, n)
                args[1] = clock.timed("pairs", args[1])
            return _fn(*args, **kwargs)

        timed = clock.timed(phase, functools.wraps(original)(with_pairs))
        for mod in list(sys.modules.values()):  # `from ... import fit` copies the name
            if getattr(mod, name, None) is original and mod.__name__.startswith("abco_train"):
                setattr(mod, name, timed)


def run_cell(task: str, method: str, seed: int, out: Path, tiny: bool) -> dict[str, Any]:
    """Train one cell here under the clock and cProfile; its phases and wall time."""
    import abco_train.methods  # noqa: F401  (registers the methods; imports their modules)
    from abco_train.bench.cells import Cell, cell_config
    from abco_train.bench.tasks import load_track
    from abco_train.config.run import RunConfig
    from abco_train.harness import loop

    for module in ("abco_train.methods.ilpo.method", "abco_train.methods.gaifo.method"):
        with contextlib.suppress(ImportError):  # an extra that is not installed
            import_module(module)
    track = load_track("headline")
    env = track.task(task).env
    cell = Cell(env, method, seed, track.task(task).settings.get("layouts"), task)
    config = cell_config(cell, out / "runs", TINY if tiny else None, 1, None, track)
    config["plots"] = False
    clock = PhaseClock()
    install(clock)
    profile = cProfile.Profile()
    start = time.perf_counter()
    clock.mark = start
    profile.enable()
    final = loop.train(RunConfig(**config))
    profile.disable()
    wall = time.perf_counter() - start
    clock._switch()
    profile.dump_stats(str(out / f"{task}-{method}.prof"))
    return {"task": task, "method": method, "seed": seed, "wall": wall,
            "status": (final or {}).get("status"), **{p: clock.seconds.get(p, 0.0)
                                                       for p in PHASES}}  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description="Seconds per phase of headline cells.")
    parser.add_argument("--out", type=Path, default=Path("runs/phases"))
    parser.add_argument("--tasks", default="", help="headline tasks (default: all)")
    parser.add_argument("--methods", default=METHODS, help="methods, comma-separated")
    parser.add_argument("--seed", type=int, default=100, help="a validation seed")
    parser.add_argument("--tiny", action="store_true", help="seconds: CartPole, two methods")
    parser.add_argument("--cell", help=argparse.SUPPRESS)  # task,method: run one, print JSON
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.cell:
        task, method = args.cell.split(",")
        print(json.dumps(run_cell(task, method, args.seed, args.out, args.tiny)))
        return 0
    from abco_train.bench.tasks import load_track

    track = load_track("headline")
    if (why := track.why_not_validation(args.seed)) is not None:  # a test seed runs once
        print(f"error: seed {args.seed} is {why}; profile on validation seeds "
              f"({track.validation_seeds})", file=sys.stderr)
        return 2
    if args.tiny:
        args.tasks, args.methods = "cartpole-authors-data", "bc,bco"
    tasks = args.tasks.split(",") if args.tasks else [t.name for t in track.tasks]
    rows = []
    header = f"{'task':<28}{'method':<18}{'wall s':>8}" + "".join(f"{p:>11}" for p in PHASES)
    print(header, flush=True)
    for task in tasks:
        for method in args.methods.split(","):
            done = subprocess.run([sys.executable, __file__, "--cell", f"{task},{method}",
                                   "--seed", str(args.seed), "--out", str(args.out),
                                   *(["--tiny"] if args.tiny else [])],
                                  capture_output=True, text=True)  # fmt: skip
            if done.returncode != 0:
                print(f"{task:<28}{method:<18} failed: {done.stderr.strip()[-300:]}")
                continue
            row = json.loads(done.stdout.strip().splitlines()[-1])
            rows.append(row)
            print(f"{task:<28}{method:<18}{row['wall']:8.1f}"
                  + "".join(f"{row[p]:11.1f}" for p in PHASES), flush=True)
    if rows:
        total = {p: sum(r[p] for r in rows) for p in (*PHASES, "wall")}
        print(f"{'all cells':<46}{total['wall']:8.1f}"
              + "".join(f"{total[p]:11.1f}" for p in PHASES))
        print(f"{'share of the wall time':<54}"
              + "".join(f"{total[p] / max(total['wall'], 1e-9):11.1%}" for p in PHASES))
        with (args.out / "phases.csv").open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return 0 if len(rows) == len(tasks) * len(args.methods.split(",")) else 1


if __name__ == "__main__":
    sys.exit(main())
