"""Family 5: bounded work.

Ranges, counts and sizes far past any real use (seeds, episodes, threads, transitions,
layouts, image sizes, ``num_envs``), records that never end (a ``config.json`` linked to a
``/dev/zero``, sparse files of 6 GiB), and Hub endpoints that never answer, drip, claim
10^12 bytes or fail every time. Every command runs under the memory limit and a hard
timeout. Held: refused in one line (or, for a Hub, ``load`` falls back to local generation)
within the limit; a run past it is a hang, a ``MemoryError`` or a traceback a failure.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

from attacks.core import (
    Case,
    Ctx,
    Outcome,
    Result,
    fail,
    json_line,
    ok,
    probe_answer,
    refused,
    run_command,
)
from attacks.fixtures import (
    bench_flags,
    copy_grid,
    copy_run,
    device,
    same_device,
    sparse,
    train_flags,
)
from attacks.hubstub import MODES, BadHub, closed_port

FAMILY = "bounds"
#: ``$ABCO_HUB_TIMEOUT`` of the Hub cases, and what a fallback may add to it (a 3x3 maze
#: dataset generated locally, on a loaded 2-core machine).
HUB_LIMIT = 10
FALLBACK_ALLOWANCE = 60
HUGE_RANGE = "0-99999999999"
SIX_GIB = 6 * 2**30


def _cli(ctx: Ctx, name: str, build: Callable[[Ctx, Path], list[str]], timeout: float = 90
         ) -> Outcome:  # fmt: skip
    base = ctx.scratch(name)
    return refused(ctx.abco(*build(ctx, base), timeout=timeout))


def _generate(ds_id: str, *sets: str) -> Callable[[Ctx, Path], list[str]]:
    flags = [x for s in sets for x in ("--set", s)]
    return lambda ctx, base: ["data", "generate", ds_id, "--out", str(base / "x.hdf5"),
                              "--quiet", *flags]  # fmt: skip


def _bench(*extra: str, envs: str = "CartPole-v1", methods: str = "bco"
           ) -> Callable[[Ctx, Path], list[str]]:  # fmt: skip
    return lambda ctx, base: ["bench", "--envs", envs, "--methods", methods, "--out",
                              str(base / "grid"), *bench_flags(ctx), *extra]  # fmt: skip


def _train(*extra: str) -> Callable[[Ctx, Path], list[str]]:
    return lambda ctx, base: ["train", *train_flags(ctx), "--run-dir", str(base / "run"),
                              *extra]  # fmt: skip


def _play(*extra: str) -> Callable[[Ctx, Path], list[str]]:
    def build(ctx: Ctx, base: Path) -> list[str]:
        run = copy_run(ctx, base / "run")
        return ["play", str(run), "--quiet", "--out", str(base / "play.gif"), *extra]

    return build


CLI_CASES: dict[str, tuple[Callable[[Ctx, Path], list[str]], bool]] = {
    "bench --seeds 0-99999999999": (_bench("--seeds", HUGE_RANGE), True),
    "bench 2 envs x 2 methods x seeds 0-99999999999": (
        _bench("--seeds", HUGE_RANGE, envs="CartPole-v1,Acrobot-v1", methods="bc,bco"), False),
    "bench --layouts 1,99999999999": (
        _bench("--seeds", "0", "--layouts", "1,99999999999", envs="AbcoMaze5x5-v0"), False),
    "bench --threads 100000": (_bench("--seeds", "0", "--threads", "100000"), False),
    "train --threads 100000": (_train("--threads", "100000"), True),
    "train --eval-episodes 1000000000000": (_train("--eval-episodes", "1000000000000"), False),
    "train --layouts 99999999999 (5x5 maze)": (
        lambda ctx, base: ["train", "--env", "AbcoMaze5x5-v0", "--layouts", "99999999999",
                           "--run-dir", str(base / "run"), "--quiet"], False),
    "play --episodes 0-99999999999": (_play("--episodes", HUGE_RANGE), True),
    "generate --set transitions=1000000000000": (
        _generate("abco/cartpole-pre-v0", "transitions=1000000000000"), True),
    "generate --set episodes=1000000000000": (
        _generate("abco/cartpole-expert-v0", "episodes=1000000000000"), False),
    "generate --set layouts=-1": (_generate("abco/maze3x3-pre-v0", "layouts=-1"), False),
    "generate --set layouts=1000000": (_generate("abco/maze3x3-pre-v0", "layouts=1000000"),
                                       False),
    "generate --set image_size=50000": (
        _generate("abco/maze3x3-expert-v0", "layouts=1", "image_size=50000"), False),
    "generate --set episodes_per_layout=1000000000000": (
        _generate("abco/maze3x3-pre-v0", "layouts=1", "episodes_per_layout=1000000000000"),
        False),
    "generate --set reference_episodes=1000000000000": (
        _generate("abco/cartpole-expert-v0", "episodes=1",
                  "reference_episodes=1000000000000"), False),
    "generate --set max_steps=1000000000000": (
        _generate("abco/maze3x3-pre-v0", "layouts=1", "max_steps=1000000000000"), False),
}  # fmt: skip


# -- endless and huge files -----------------------------------------------------------------


def _zero(path: Path) -> bool:
    """``path``: a link to a private ``/dev/zero`` (the machine's where mknod is refused;
    only ever read through the link)."""
    target = path.parent / f".{path.name}.zero"
    if not device(target, "zero"):
        target = Path("/dev/zero")
    if path.exists() or path.is_symlink():
        path.unlink()
    path.symlink_to(target)
    return target != Path("/dev/zero")


def _endless(ctx: Ctx, name: str, where: str, file: str, how: str) -> Outcome:
    """A record of a run folder or grid that never ends (``how``: ``zero`` or ``sparse``)."""
    base = ctx.scratch(name)
    if where == "grid":
        folder = copy_grid(ctx, base / "grid")
        path = folder / file
    else:
        folder = copy_run(ctx, base / "run", final=where != "resume")
        path = folder / file
    private = True
    if how == "zero":
        private = _zero(path)
    else:
        path.unlink(missing_ok=True)
        sparse(path, SIX_GIB)
    if where == "grid":
        res = ctx.abco("report", str(folder), "--out", str(base / "report"), timeout=90)
    elif where == "play":
        res = ctx.abco("play", str(folder), "--episodes", "0", "--quiet", "--out",
                       str(base / "p.gif"), timeout=90)  # fmt: skip
    else:
        res = ctx.abco("train", *train_flags(ctx), "--run-dir", str(folder), timeout=90)
    target = path.parent / f".{path.name}.zero"
    if how == "zero" and private and not same_device(target, "zero"):
        return fail("special", f"the /dev/zero copy behind {file} was replaced")
    if where == "grid" and res.rc == 0 and not res.timed_out:  # it may name and skip it
        said = res.out + res.err + _read(base / "report" / "report.md")
        hint = "seed0" if "seed0" in file else file
        return ok("named and skipped") if hint in said \
            else fail("silent", f"report ran without a word about {file}")  # fmt: skip
    return refused(res)


def _read(path: Path) -> str:
    try:
        return path.read_text(errors="replace")[:200000]
    except OSError:
        return ""


ENDLESS = [
    ("play", "config.json", "zero"), ("resume", "config.json", "zero"),
    ("resume", "metrics.jsonl", "zero"), ("play", "config.json", "sparse"),
    ("train", "final.json", "sparse"), ("grid", "results.jsonl", "zero"),
    ("grid", "results.jsonl", "sparse"), ("grid", "CartPole-v1/bco/seed0/final.json", "zero"),
    ("grid", "CartPole-v1/bco/seed0/final.json", "sparse"),
    ("grid", "CartPole-v1/bco/seed0/metrics.jsonl", "zero"), ("grid", "bench_log.jsonl", "zero"),
]  # fmt: skip


# -- Python calls ---------------------------------------------------------------------------

_CALL = """
import json, sys
import gymnasium as gym, abco_envs, abco_data
try:
    {call}
except MemoryError as exc:
    print(json.dumps({{"error": "MemoryError", "message": str(exc)}}))
except Exception as exc:
    print(json.dumps({{"error": type(exc).__name__, "message": str(exc)[:300]}}))
else:
    print(json.dumps({{"accepted": True}}))
"""

API_CASES = {
    "gym.make(image_size=(50000, 50000))":
        'gym.make("AbcoMaze5x5-v0", image_size=(50000, 50000)).reset(seed=0)',
    "gym.make(image_size=50000)": 'gym.make("AbcoMaze5x5-v0", image_size=50000).reset(seed=0)',
    "gym.make_vec(num_envs=10**6)":
        'gym.make_vec("AbcoMaze5x5-v0", num_envs=10**6,'
        ' vectorization_mode="vector_entry_point").reset(seed=0)',
    "gym.make_vec(num_envs=10**6, image_size=64)":
        'gym.make_vec("AbcoMaze3x3-v0", num_envs=10**6, image_size=64,'
        ' vectorization_mode="vector_entry_point").reset(seed=0)',
    "abco_data.generate(transitions=10**12)":
        'abco_data.generate("abco/cartpole-pre-v0", sys.argv[1] + "/x.hdf5", progress=False,'
        " transitions=10**12)",
    "abco_data.load(layouts=10**12)":
        'abco_data.load("abco/maze5x5-procedural-expert-v0", layouts=10**12, progress=False)',
}  # fmt: skip


def api(ctx: Ctx, name: str, call: str) -> Outcome:
    base = ctx.scratch(name)
    res = ctx.python(_CALL.format(call=call), str(base), timeout=90)
    failed, answer = probe_answer(res, accepted="accepted")
    if failed is not None:
        return failed
    if answer["error"] == "MemoryError":
        return fail("traceback", "MemoryError: allocated before checking the size")
    return ok(f"{answer['error']}: {answer['message'][:150]}")


# -- the Hub --------------------------------------------------------------------------------

_LOAD = """
import json, sys, time
import abco_data
t = time.monotonic()
ds = abco_data.load(sys.argv[1], progress=False)
print(json.dumps({"path": str(ds.path), "seconds": time.monotonic() - t}))
"""


def _hub_env(ctx: Ctx, base: Path, endpoint: str, manifest: str) -> dict[str, str]:
    env = {**ctx.env, "HF_ENDPOINT": endpoint, "ABCO_DATA_MANIFEST": manifest,
           "ABCO_HUB_TIMEOUT": str(HUB_LIMIT), "ABCO_DATA_HOME": str(base / "abco"),
           "HF_HOME": str(base / "hf")}  # fmt: skip
    env.pop("HF_HUB_OFFLINE", None)
    return env


def _fell_back(res: Result, limit: float) -> Outcome:
    if res.timed_out:
        return fail("hang", f"load still running after {res.timeout:.0f} s")
    answer = json_line(res)
    if res.rc != 0 or answer is None:
        return fail("traceback", res.summary())
    if answer["seconds"] > limit:
        return fail("hang", f"load took {answer['seconds']:.0f} s (limit {limit:.0f} s)")
    return ok(f"loaded in {answer['seconds']:.1f} s")


def hub_load(ctx: Ctx, mode: str) -> Outcome:
    """``abco_data.load`` against a misbehaving Hub: falls back within the limit."""
    hub = ctx.fixture("hub")
    base = ctx.scratch(f"hub {mode}")
    limit = HUB_LIMIT + FALLBACK_ALLOWANCE
    if mode == "refused":
        env = _hub_env(ctx, base, f"http://127.0.0.1:{closed_port()}", hub["manifest"])
        return _fell_back(ctx.python(_LOAD, hub["id"], env=env, timeout=limit + 30), limit)
    entry = hub["entry"]
    with BadHub(mode, hub["revision"], entry["size"], entry["sha256"]) as server:
        env = _hub_env(ctx, base, server.url, hub["manifest"])
        res = ctx.python(_LOAD, hub["id"], env=env, timeout=limit + 30)
    return _fell_back(res, limit)


def hub_download_cli(ctx: Ctx, mode: str) -> Outcome:
    """``abco data download`` against a misbehaving Hub: one error line within the limit."""
    hub = ctx.fixture("hub")
    base = ctx.scratch(f"hub download {mode}")
    entry = hub["entry"]
    with BadHub(mode, hub["revision"], entry["size"], entry["sha256"]) as server:
        env = _hub_env(ctx, base, server.url, hub["manifest"])
        res = ctx.abco("data", "download", hub["id"], "--quiet", env=env,
                       timeout=HUB_LIMIT + 30)  # fmt: skip
    return refused(res)


def hub_bad_limit(ctx: Ctx, value: str) -> Outcome:
    """A ``$ABCO_HUB_TIMEOUT`` that is no limit: refused in one line."""
    hub = ctx.fixture("hub")
    base = ctx.scratch(f"hub limit {value}")
    with BadHub("silent", hub["revision"]) as server:
        env = {**_hub_env(ctx, base, server.url, hub["manifest"]), "ABCO_HUB_TIMEOUT": value}
        res = ctx.abco("data", "download", hub["id"], "--quiet", env=env, timeout=60)
    return refused(res)


def hub_good(ctx: Ctx, interrupted: bool) -> Outcome:
    """A well-behaved Hub (tests/data/hub_server.py): downloaded; one that drops every
    transfer half-way: generated instead, within the limit."""
    from attacks.core import ROOT

    sys.path.insert(0, str(ROOT / "tests" / "data"))
    from hub_server import HubServer  # type: ignore[import-not-found]

    hub = ctx.fixture("hub")
    base = ctx.scratch(f"hub good {interrupted}")
    with HubServer() as server:
        commit = server.publish("abco-datasets/abco", {hub["entry"]["filename"]: hub["data"]})
        manifest = json.loads(Path(hub["manifest"]).read_text())
        manifest["revision"] = commit
        path = base / "manifest.json"
        path.write_text(json.dumps(manifest))
        if interrupted:
            server.interrupt(hub["entry"]["filename"], after=1000, times=None)
        env = _hub_env(ctx, base, server.url, str(path))
        res = run_command([sys.executable, "-c", _LOAD, hub["id"]], env=env,
                          timeout=HUB_LIMIT + FALLBACK_ALLOWANCE + 30, memory=ctx.memory,
                          cwd=ctx.root)  # fmt: skip
        gets = [r for r in server.requests if r.method == "GET" and "/resolve/" in r.path]
    outcome = _fell_back(res, HUB_LIMIT + FALLBACK_ALLOWANCE)
    if not outcome.failed and not interrupted and not gets:
        return fail("silent", "the Hub was never asked (is HF_ENDPOINT honoured?)")
    return outcome


def cases() -> list[Case]:
    """Huge ranges and sizes, endless records, and misbehaving Hubs."""
    out = [Case(FAMILY, name, partial(_cli, name=name, build=build), quick=quick)
           for name, (build, quick) in CLI_CASES.items()]  # fmt: skip
    for where, file, how in ENDLESS:
        name = f"{where}: {file} is {'/dev/zero' if how == 'zero' else 'a 6 GiB sparse file'}"
        out.append(Case(FAMILY, name, partial(_endless, name=name, where=where, file=file,
                                              how=how), quick=(where, how) == ("play", "zero")))
    out += [Case(FAMILY, name, partial(api, name=name, call=call),
                 quick=name.startswith("gym.make(image_size=("))
            for name, call in API_CASES.items()]  # fmt: skip
    out += [Case(FAMILY, f"Hub {mode}: load falls back", partial(hub_load, mode=mode),
                 quick=mode == "silent") for mode in (*MODES, "refused")]  # fmt: skip
    out += [Case(FAMILY, f"Hub {mode}: data download, one line", partial(hub_download_cli,
                                                                         mode=mode))
            for mode in ("silent", "drip-body", "huge")]  # fmt: skip
    out += [Case(FAMILY, f"ABCO_HUB_TIMEOUT={v}", partial(hub_bad_limit, value=v))
            for v in ("nan", "-1", "abc", "1e400")]  # fmt: skip
    out += [Case(FAMILY, "Hub well-behaved: downloaded", partial(hub_good, interrupted=False)),
            Case(FAMILY, "Hub drops every transfer: generated",
                 partial(hub_good, interrupted=True))]  # fmt: skip
    return out
