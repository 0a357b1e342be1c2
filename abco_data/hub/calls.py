"""Calls to the Hugging Face Hub with a total time limit, a bound on the bytes, and quiet logs.

huggingface_hub gives each request its own timeouts (``HF_HUB_ETAG_TIMEOUT``,
``HF_HUB_DOWNLOAD_TIMEOUT``) and retries a failed one several times, resuming a download that
stalls: a server that accepts and never answers, or drips a byte at a time, could keep a call
going for many minutes. :func:`call_hub` bounds the whole call (connection, answers, every
retry) by one limit, ``$ABCO_HUB_TIMEOUT`` seconds (:data:`DEFAULT_HUB_TIMEOUT` when unset):

- the call runs in a worker thread; when the limit passes, :func:`call_hub` raises
  :class:`HubCallStopped` at once, whatever the worker is waiting for;
- while it runs, two event hooks on huggingface_hub's own HTTP client (the one
  :func:`huggingface_hub.get_session` returns) shorten each request's timeouts to the time
  left (and a second, so that the limit, not a request's timeout, is what the caller meets)
  and check every chunk of an answer: a worker past its limit stops at its next request or
  chunk instead of carrying on in the background. They also refuse an answer larger than
  the file asked for (``max_bytes``): a Hub that announces 10**12 bytes for a file of 300 kB is
  refused before its body is read;
- huggingface_hub's retry warnings are held back while the call runs (unless its logging was
  made more verbose, ``HF_HUB_VERBOSITY=info``): the caller reports the failure in one line.

Example:
    >>> call_hub(lambda: 6 * 7, timeout=5)
    42
    >>> hub_timeout(None) > 0
    True
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any, TypeVar

from huggingface_hub import get_session
from huggingface_hub.utils import httpx

from abco_data.errors import InvalidParameterError

__all__ = ["DEFAULT_HUB_TIMEOUT", "HUB_TIMEOUT_ENV", "MAX_HUB_TIMEOUT", "HubCallStopped",
           "call_hub", "hub_timeout"]

T = TypeVar("T")

#: Environment variable: the total time limit of one Hub call, in seconds.
HUB_TIMEOUT_ENV = "ABCO_HUB_TIMEOUT"
#: The limit when ``$ABCO_HUB_TIMEOUT`` is unset (a 300 kB to 100 MB file on a usual line).
DEFAULT_HUB_TIMEOUT = 60.0
#: The largest limit accepted: one day.
MAX_HUB_TIMEOUT = 86_400.0
#: A request's timeouts end this long after the call's limit, which the caller meets first.
_TIMEOUT_MARGIN = 1.0
#: An error answer (4xx, 5xx) is a short message: never read more of one than this.
_ERROR_BODY_BYTES = 1 << 20
_HF_LOGGER = "huggingface_hub"


class HubCallStopped(httpx.HTTPError):
    """abco stopped a Hub call: its time limit passed, or the answer was larger than the file
    asked for. Not one of the errors huggingface_hub retries."""


@dataclass
class _Limits:
    deadline: float
    limit: float
    max_bytes: int | None
    stopped: threading.Event = field(default_factory=threading.Event)

    def time_left(self) -> float:
        """Seconds left; raises :class:`HubCallStopped` when none are."""
        left = self.deadline - time.monotonic()
        if left <= 0 or self.stopped.is_set():
            raise HubCallStopped(f"no complete answer within {self.limit:g} s (the limit"
                                 f" {HUB_TIMEOUT_ENV} sets)")
        return left


#: The limits of the Hub call running in this thread (None: not an abco call, hooks idle).
_LIMITS: ContextVar[_Limits | None] = ContextVar("abco_hub_limits", default=None)


def hub_timeout(value: float | str | None = None) -> float:
    """The total time limit of a Hub call: ``value``, else ``$ABCO_HUB_TIMEOUT``, else
    :data:`DEFAULT_HUB_TIMEOUT`.

    Raises:
        InvalidParameterError: Not a number of seconds above 0 and at most
            :data:`MAX_HUB_TIMEOUT`.
    """
    source = "timeout"
    if value is None:
        value, source = os.environ.get(HUB_TIMEOUT_ENV) or DEFAULT_HUB_TIMEOUT, HUB_TIMEOUT_ENV
    try:
        seconds = float(value)
    except (TypeError, ValueError):
        seconds = math.nan
    if not 0 < seconds <= MAX_HUB_TIMEOUT:  # NaN fails too
        raise InvalidParameterError(f"{source} must be a number of seconds above 0 and at most"
                                    f" {MAX_HUB_TIMEOUT:g}, got {value!r}")
    return seconds


class _BoundedStream(httpx.SyncByteStream):
    """An answer's body, checked against the limits at every chunk."""

    def __init__(self, stream: httpx.SyncByteStream, limits: _Limits, max_bytes: int | None,
                 url: object) -> None:
        self._stream, self._limits, self._max_bytes, self._url = stream, limits, max_bytes, url

    def __iter__(self) -> Iterator[bytes]:
        seen = 0
        for chunk in self._stream:
            self._limits.time_left()
            seen += len(chunk)
            if self._max_bytes is not None and seen > self._max_bytes:
                raise HubCallStopped(f"{self._url} sent more than the {self._max_bytes} bytes"
                                     " expected")
            yield chunk

    def close(self) -> None:
        self._stream.close()


def _on_request(request: httpx.Request) -> None:
    """Event hook: each timeout of the request at most the time left."""
    limits = _LIMITS.get()
    if limits is None:
        return
    left = limits.time_left() + _TIMEOUT_MARGIN
    given = dict(request.extensions.get("timeout") or {})
    request.extensions["timeout"] = {
        key: left if given.get(key) is None else min(float(given[key]), left)
        for key in ("connect", "read", "write", "pool")}


def _on_response(response: httpx.Response) -> None:
    """Event hook: refuse an answer announced larger than expected; bound its body."""
    limits = _LIMITS.get()
    if limits is None:
        return
    limits.time_left()
    max_bytes = limits.max_bytes if response.is_success else _ERROR_BODY_BYTES
    if max_bytes is not None:
        for header in ("x-linked-size", "content-length"):
            announced = response.headers.get(header, "").strip()
            if announced.isdigit() and int(announced) > max_bytes:
                raise HubCallStopped(f"{response.url} announces {int(announced)} bytes, more"
                                     f" than the {max_bytes} expected")
    if isinstance(response.stream, httpx.SyncByteStream):
        response.stream = _BoundedStream(response.stream, limits, max_bytes, response.url)


def _install_hooks() -> None:
    """Add the hooks to huggingface_hub's shared client (once; idle outside :func:`call_hub`)."""
    client = get_session()
    hooks = client.event_hooks
    if _on_request not in hooks.get("request", []):
        client.event_hooks = {"request": [*hooks.get("request", []), _on_request],
                              "response": [*hooks.get("response", []), _on_response]}


@contextmanager
def _quiet_hub_logs() -> Iterator[None]:
    """Hold back huggingface_hub's warnings (retries) unless its logging is more verbose."""
    hf_logger = logging.getLogger(_HF_LOGGER)
    before = hf_logger.level
    quiet = hf_logger.getEffectiveLevel() >= logging.WARNING
    if quiet:
        hf_logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        if quiet:
            hf_logger.setLevel(before)


def call_hub(fn: Callable[[], T], *, timeout: float | None = None,
             max_bytes: int | None = None) -> T:
    """``fn()``, a call of huggingface_hub, within a total time limit.

    Args:
        fn: The call.
        timeout: Seconds; default :func:`hub_timeout` (``$ABCO_HUB_TIMEOUT``).
        max_bytes: The most bytes one successful answer may have (the file's size).

    Returns:
        What ``fn`` returned.

    Raises:
        HubCallStopped: The limit passed, or an answer was larger than ``max_bytes``.
        InvalidParameterError: A bad limit (see :func:`hub_timeout`).
        BaseException: Whatever ``fn`` raised.
    """
    limit = hub_timeout(timeout)
    limits = _Limits(time.monotonic() + limit, limit, max_bytes)
    outcome: dict[str, Any] = {}
    done = threading.Event()

    def work() -> None:
        _LIMITS.set(limits)
        try:
            outcome["value"] = fn()
        except BaseException as err:  # noqa: BLE001 - handed to the caller
            outcome["error"] = err
        finally:
            done.set()

    with _quiet_hub_logs():
        _install_hooks()
        worker = threading.Thread(target=work, name="abco-hub-call", daemon=True)
        worker.start()
        try:
            finished = done.wait(limit)
        finally:
            if not done.is_set():
                limits.stopped.set()  # the worker stops at its next request or chunk
    if not finished:
        limits.time_left()  # raises HubCallStopped
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]
