"""Running a function in a forked child process with a time limit.

A damaged file can make a native library loop or crash; run in a child, such a failure costs
the child, and the parent learns what happened (:class:`ChildOutcome`). ``abco data verify``
checks files this way, and the fuzz tests count hangs and crashes with it.

Example:
    >>> run_in_child(lambda: 6 * 7, timeout=30).value
    42
    >>> run_in_child(lambda: os.kill(os.getpid(), 9), timeout=30).signal
    'SIGKILL'
"""

from __future__ import annotations

import os
import pickle
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["ChildOutcome", "run_in_child"]


@dataclass(frozen=True)
class ChildOutcome:
    """How a child ended.

    Attributes:
        finished: ``fn`` returned or raised (see ``value`` and ``error``).
        value: What ``fn`` returned.
        error: What ``fn`` raised (pickled across), or None.
        timed_out: The child ran past the time limit and was killed.
        signal: The name of the signal that killed the child (a crash), or None.
    """

    finished: bool
    value: Any = None
    error: BaseException | None = None
    timed_out: bool = False
    signal: str | None = None


def _report(fn: Callable[[], Any], write: int) -> None:
    """In the child: run ``fn`` and send its outcome to the parent."""
    try:
        outcome = ChildOutcome(True, value=fn())
    except BaseException as err:  # noqa: BLE001 - handed to the parent
        outcome = ChildOutcome(True, error=err)
    with os.fdopen(write, "wb") as out:
        try:
            pickle.dump(outcome, out)
        except Exception as err:  # noqa: BLE001 - an unpicklable result
            pickle.dump(ChildOutcome(True, error=RuntimeError(f"unpicklable outcome: {err}")),
                        out)


def run_in_child(fn: Callable[[], Any], timeout: float) -> ChildOutcome:
    """Run ``fn()`` in a forked child; wait at most ``timeout`` seconds.

    The outcome must be small (a pipe's buffer, 64 KiB): the child writes it when done.
    """
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        os.close(read)
        try:
            _report(fn, write)
        finally:
            os._exit(0)
    os.close(write)
    deadline = time.monotonic() + timeout
    with os.fdopen(read, "rb") as source:
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            if time.monotonic() > deadline:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                return ChildOutcome(False, timed_out=True)
            time.sleep(0.002)
        data = source.read()
    if os.WIFSIGNALED(status):
        return ChildOutcome(False, signal=signal.Signals(os.WTERMSIG(status)).name)
    if not data:
        return ChildOutcome(False, signal=f"exit status {os.WEXITSTATUS(status)}")
    return pickle.loads(data)
