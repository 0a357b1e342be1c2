"""The attack harness's core: outcome classes, cases, the run context, commands and judges.

Every command of a case runs in a fresh process of its own session (so a timeout kills its
children too), under ``RLIMIT_AS`` (a runaway allocation fails fast instead of eating the
machine), with a hard timeout (a run past it counts as a hang), and with ``ABCO_DATA_HOME``
and ``HF_HOME`` inside the scratch folder: nothing touches the user's caches.
"""

from __future__ import annotations

import hashlib
import itertools
import os
import re
import resource
import signal
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The repository (tools/attacks/core.py -> the root).
ROOT = Path(__file__).resolve().parents[2]

#: The failure classes, in the table's order: key -> column header.
FAILURES = {
    "code": "code",
    "special": "special",
    "lost": "lost",
    "mixed": "mixed",
    "silent": "silent",
    "hang": "hangs",
    "traceback": "traceback",
    "script": "script",
}
#: What each failure class means (printed under the table).
LEGEND = {
    "code": "code from a file was executed",
    "special": "a device, FIFO or directory was replaced (or written through a link)",
    "lost": "rows of results.jsonl, or files that were there, lost or changed",
    "mixed": "a run folder's config, checkpoint and final result of different runs",
    "silent": "wrong input accepted, or wrong data returned, without a word",
    "hang": "still running at the case's hard limit",
    "traceback": "a traceback, a crash, or no single clear error line",
    "script": "this script's own error (or a fixture it could not build)",
}
PASS, SKIP = "pass", "skip"

#: A line abco (or argparse, for a usage error) prints for bad input or a failed operation.
ERROR_LINE = re.compile(r"^(?:[\w.\- ]+: )?error: \S")
#: What a traceback, an uncaught exception or a crash leaves on stderr.
TRACEBACK = re.compile(
    r"Traceback \(most recent call last\)|^\s+File \".*\", line \d+|"
    r"^(?:[A-Za-z_][\w.]*\.)?[A-Z]\w*(?:Error|Exception)\b(?::|$)|^MemoryError|"
    r"Segmentation fault|core dumped|^Fatal Python error",
    re.M,
)


@dataclass(frozen=True)
class Outcome:
    """What one case came to: ``pass``, ``skip`` or a failure class of :data:`FAILURES`."""

    verdict: str
    detail: str = ""

    @property
    def failed(self) -> bool:
        """Whether the verdict is a failure class."""
        return self.verdict in FAILURES


def ok(detail: str = "") -> Outcome:
    """The case held."""
    return Outcome(PASS, detail)


def skip(why: str) -> Outcome:
    """The case could not be tried here (e.g. mounting is not allowed)."""
    return Outcome(SKIP, why)


def fail(kind: str, detail: str) -> Outcome:
    """A failure of class ``kind`` (a key of :data:`FAILURES`)."""
    if kind not in FAILURES:
        raise ValueError(f"unknown failure class {kind!r}")
    return Outcome(kind, detail)


@dataclass(frozen=True)
class Case:
    """One attack: ``run(ctx)`` tries it and judges what happened.

    Attributes:
        family: The family's name in the table.
        name: Short, unique within the family.
        run: The attack and its judgement.
        quick: Part of the ``--quick`` subset.
    """

    family: str
    name: str
    run: Callable[[Ctx], Outcome]
    quick: bool = False


class FixtureError(RuntimeError):
    """A shared fixture (tiny datasets, a trained run, a grid) could not be built."""


@dataclass
class Result:
    """A finished (or killed) command."""

    argv: list[str]
    rc: int | None  # None: killed at its timeout
    out: str
    err: str
    seconds: float
    timeout: float

    @property
    def timed_out(self) -> bool:
        """Killed at the hard timeout."""
        return self.rc is None

    def summary(self) -> str:
        """Exit code and the most telling stderr (else stdout) line."""
        code = "killed at the timeout" if self.rc is None else f"exit {self.rc}"
        return f"{code}: {telling_line(self.err) or telling_line(self.out) or '(no output)'}"


def telling_line(text: str) -> str:
    """The line that best says what went wrong: an exception line, else an error line, else
    the last line (shortened)."""
    lines = [x.strip() for x in text.splitlines() if x.strip()]
    for pattern in (TRACEBACK, ERROR_LINE):
        found = [x for x in lines if pattern.search(x) and not x.startswith(("File ", "Traceback"))]
        if found:
            return found[-1][:220]
    return lines[-1][:220] if lines else ""


def _limit_memory(limit: int) -> Callable[[], None]:
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return apply


def run_command(argv: Sequence[str], *, env: dict[str, str], timeout: float,
                memory: int, cwd: str | os.PathLike[str] | None = None,
                stdin: bytes | None = None) -> Result:  # fmt: skip
    """Run ``argv`` in a session of its own under ``RLIMIT_AS = memory``; kill it (and its
    children) at ``timeout`` seconds."""
    t0 = time.monotonic()
    proc = subprocess.Popen(
        list(argv), stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=cwd,
        start_new_session=True, preexec_fn=_limit_memory(memory),
    )  # fmt: skip
    rc: int | None
    try:
        out, err = proc.communicate(input=stdin, timeout=timeout)
        rc = proc.returncode
    except subprocess.TimeoutExpired:
        kill_group(proc.pid)
        try:
            out, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            out, err = b"", b""
        rc = None
    kill_group(proc.pid)  # workers a finished command left behind
    return Result(list(argv), rc, out.decode(errors="replace"), err.decode(errors="replace"),
                  time.monotonic() - t0, timeout)  # fmt: skip


def kill_group(pid: int) -> None:
    """SIGKILL the session a command ran in (it and whatever it started)."""
    with suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGKILL)


def base_env(root: Path, code: Path = ROOT) -> dict[str, str]:
    """The environment of every command: the user's, less the Hub's and abco's settings,
    with the caches in ``root``, offline, headless and without progress bars, and the abco
    checkout ``code`` first on the path."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("HF_", "ABCO_", "HUGGINGFACE"))}  # fmt: skip
    env.update({
        "ABCO_DATA_HOME": str(root / "cache" / "abco"),
        "HF_HOME": str(root / "cache" / "hf"),
        "HF_HUB_OFFLINE": "1",
        "HF_HUB_DISABLE_PROGRESS_BARS": "1",
        "HF_HUB_DISABLE_TELEMETRY": "1",
        "SDL_VIDEODRIVER": "dummy",
        "SDL_AUDIODRIVER": "dummy",
        "MPLBACKEND": "Agg",
        "XDG_RUNTIME_DIR": str(root / "xdg"),
        "TQDM_DISABLE": "1",
        "PYTHONPATH": os.pathsep.join([str(code), *filter(None, [env.get("PYTHONPATH")])]),
    })  # fmt: skip
    return env


class Ctx:
    """What a case gets: a scratch folder, the commands, the shared fixtures.

    Args:
        root: The run's scratch folder (everything any case writes lies under it).
        memory_gib: ``RLIMIT_AS`` of every command.
        fixtures: Name -> builder of the shared fixtures (:mod:`attacks.fixtures`).
        code: The abco checkout the commands import (default this repository).
    """

    def __init__(self, root: Path, memory_gib: float,
                 fixtures: dict[str, Callable[[Ctx], Any]], code: Path = ROOT) -> None:  # fmt: skip
        self.root = root
        self.code = code
        self.memory = int(memory_gib * 2**30)
        self.env = base_env(root, code)
        (root / "xdg").mkdir(parents=True, exist_ok=True, mode=0o700)
        self._builders = fixtures
        self._built: dict[str, Any] = {}
        self._locks = {name: threading.Lock() for name in fixtures}
        self._count = itertools.count()
        self._count_lock = threading.Lock()

    def scratch(self, name: str) -> Path:
        """A fresh, empty folder for one case."""
        with self._count_lock:
            n = next(self._count)
        slug = re.sub(r"[^A-Za-z0-9]+", "-", name).strip("-")[:40]
        path = self.root / "cases" / f"{n:03d}-{slug}"
        path.mkdir(parents=True)
        return path

    def fixture(self, name: str) -> Any:
        """A shared fixture, built on first use (once, whichever case asks first)."""
        with self._locks[name]:
            if name not in self._built:
                try:
                    self._built[name] = self._builders[name](self)
                except FixtureError as exc:
                    self._built[name] = exc
            value = self._built[name]
        if isinstance(value, FixtureError):
            raise value
        return value

    def abco(self, *args: str, timeout: float = 120, env: dict[str, str] | None = None,
             cwd: str | os.PathLike[str] | None = None, stdin: bytes | None = None) -> Result:
        """``python -m abco_train ARGS`` (the ``abco`` command), in ``cwd`` (default the
        scratch folder: never the repository, whose checkout would shadow ``--code``)."""
        return run_command([sys.executable, "-m", "abco_train", *args], env=env or self.env,
                           timeout=timeout, memory=self.memory, cwd=cwd or self.root,
                           stdin=stdin)  # fmt: skip

    def python(self, code: str, *args: str, timeout: float = 120,
               env: dict[str, str] | None = None) -> Result:  # fmt: skip
        """``python -c CODE ARGS``, in the scratch folder."""
        return run_command([sys.executable, "-c", code, *args], env=env or self.env,
                           timeout=timeout, memory=self.memory, cwd=self.root)


# -- judges ---------------------------------------------------------------------------------


def refused(res: Result, *, mention: str | tuple[str, ...] | None = None,
            codes: Sequence[int] = (1, 2)) -> Outcome:  # fmt: skip
    """Bad input (or a failed operation) told in one line: exit 1 or 2, exactly one
    ``error: ...`` line on stderr (the last), nothing that looks like a traceback; where
    ``mention`` is given, the line holds it (or one of them)."""
    if res.timed_out:
        return fail("hang", f"still running after {res.timeout:.0f} s")
    if TRACEBACK.search(res.err):
        return fail("traceback", res.summary())
    if res.rc == 0:
        return fail("silent", f"accepted (exit 0): {telling_line(res.out) or '(no output)'}")
    if res.rc not in codes:
        return fail("traceback", res.summary())
    lines = [x for x in res.err.splitlines() if x.strip()]
    errors = [x for x in lines if ERROR_LINE.match(x)]
    if len(errors) != 1:
        return fail("traceback", f"exit {res.rc} with {len(errors)} error lines: "
                    f"{telling_line(res.err) or '(no stderr)'}")  # fmt: skip
    if lines[-1] != errors[0]:
        return fail("traceback", f"exit {res.rc}, the error line is not the last: {lines[-1]}")
    words = (mention,) if isinstance(mention, str) else mention or ()
    if words and not any(w in errors[0] for w in words):
        return fail("traceback", f"the error line does not name {' or '.join(words)}: "
                    f"{errors[0][:200]}")  # fmt: skip
    return ok(errors[0][:200])


def succeeded(res: Result) -> Outcome:
    """A command that should work: exit 0, no traceback."""
    if res.timed_out:
        return fail("hang", f"still running after {res.timeout:.0f} s")
    if res.rc != 0 or TRACEBACK.search(res.err):
        return fail("traceback", res.summary())
    return ok()


# -- files ----------------------------------------------------------------------------------

_HASHED = 64 * 2**20  # files larger than this are compared by size and mtime


def snapshot(path: Path) -> dict[str, tuple[Any, ...]]:
    """Every entry under ``path`` (itself included): its kind and content (or link target)."""
    out: dict[str, tuple[Any, ...]] = {}
    entries = [path]
    if path.is_dir() and not path.is_symlink():
        for folder, dirs, files in os.walk(path):
            entries += [Path(folder) / n for n in dirs + files]
    for entry in entries:
        try:
            st = entry.lstat()
        except OSError:
            continue
        key = entry.relative_to(path).as_posix()
        if stat.S_ISREG(st.st_mode):
            if st.st_size <= _HASHED:
                out[key] = ("file", hashlib.sha256(entry.read_bytes()).hexdigest())
            else:
                out[key] = ("file", st.st_size, st.st_mtime_ns)
        elif stat.S_ISLNK(st.st_mode):
            out[key] = ("link", os.readlink(entry))
        else:
            out[key] = (stat.S_IFMT(st.st_mode), st.st_rdev)
    return out


def changed(before: dict[str, tuple[Any, ...]], path: Path) -> list[str]:
    """The entries of ``before`` that are gone or different now."""
    after = snapshot(path)
    return sorted(k for k, v in before.items() if after.get(k) != v)


def kept(before: dict[str, tuple[Any, ...]], path: Path, outcome: Outcome) -> Outcome:
    """``outcome``, unless something that was under ``path`` was lost or changed."""
    gone = changed(before, path)
    if gone and not outcome.failed:
        return fail("lost", f"changed or removed: {', '.join(gone[:4])}")
    return outcome


def kind_of(path: Path) -> str:
    """``file``, ``dir``, ``link``, ``char``, ``fifo``, ``other`` or ``missing`` (no link
    followed)."""
    try:
        mode = path.lstat().st_mode
    except FileNotFoundError:
        return "missing"
    for test, name in ((stat.S_ISLNK, "link"), (stat.S_ISREG, "file"), (stat.S_ISDIR, "dir"),
                       (stat.S_ISCHR, "char"), (stat.S_ISFIFO, "fifo")):  # fmt: skip
        if test(mode):
            return name
    return "other"


def json_line(res: Result) -> dict[str, Any] | None:
    """The last stdout line of a probe, as JSON (``None`` if there is none)."""
    import json

    for line in reversed(res.out.splitlines()):
        if line.startswith("{"):
            with suppress(ValueError):
                value = json.loads(line)
                return value if isinstance(value, dict) else None
    return None


def probe_answer(res: Result, accepted: str = "loaded") -> tuple[Outcome | None, dict[str, Any]]:
    """A Python probe that must refuse: a failure when it hung, printed no answer or was
    ``accepted`` (its answer's key); else ``None`` and its answer."""
    if res.timed_out:
        return fail("hang", f"still running after {res.timeout:.0f} s"), {}
    answer = json_line(res)
    if answer is None:
        return fail("traceback", res.summary()), {}
    if answer.get(accepted):
        return fail("silent", f"{accepted} without an error"), answer
    return None, answer
