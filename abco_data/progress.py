"""Progress that suits both a terminal and a log: :func:`progress_bar`.

On a terminal it is a tqdm bar, redrawn in place. When the output is not a terminal (a log
file, a pipe, a batch job) a redrawn bar becomes hundreds of lines of carriage returns:
:class:`LogProgress` writes whole lines instead, one when the bar starts, one each time
another tenth of the total is done, and one when it closes (a dozen lines in all, however
long the loop). Both are tqdm objects (``update``, ``set_postfix``, ``write``, ``close``,
iteration), so one call site serves both; the trainer and the data layer share this helper.

Example:
    >>> import io
    >>> log = io.StringIO()
    >>> with progress_bar(total=1000, desc="episodes", file=log) as bar:
    ...     for _ in range(1000):
    ...         _ = bar.update(1)
    >>> lines = log.getvalue().splitlines()
    >>> len(lines), lines[0].startswith("episodes:   0%"), "100%" in lines[-1]
    (11, True, True)
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable
from typing import Any, TextIO

from tqdm.std import tqdm

__all__ = ["LogProgress", "progress_bar", "log_progress_class", "is_terminal",
           "LOG_EVERY", "LOG_SECONDS"]

#: The share of the total between two lines of :class:`LogProgress`.
LOG_EVERY = 0.1
#: Without a known total, :class:`LogProgress` writes a line at most this often (seconds).
LOG_SECONDS = 60.0
_LINE_FORMAT = ("{desc}: {percentage:3.0f}% {n_fmt}/{total_fmt} {unit}"
                " [{elapsed}<{remaining}{postfix}]")


def is_terminal(stream: Any) -> bool:
    """Whether ``stream`` is an interactive terminal."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # no isatty, or a closed stream
        return False


class LogProgress(tqdm):
    """A tqdm bar that writes whole lines: at the start, every ``every`` of the total, at
    the end (without a total: at most every :data:`LOG_SECONDS`). Never a carriage return.

    Takes tqdm's arguments, and ``name`` (huggingface_hub passes one to its bars; ignored).
    """

    def __init__(self, *args: Any, every: float = LOG_EVERY, **kwargs: Any) -> None:
        kwargs.pop("name", None)
        kwargs.setdefault("bar_format", _LINE_FORMAT)
        kwargs.setdefault("mininterval", 0)  # display() decides, by counts, never by time
        total = kwargs.get("total")
        if total is None and hasattr(args[0] if args else kwargs.get("iterable"), "__len__"):
            total = len(args[0] if args else kwargs["iterable"])
        if total and "miniters" not in kwargs:  # refresh a few times a line, not every step
            kwargs["miniters"] = max(1, int(total * every / 4))
        self._every = every
        self._printed_n: float | None = None
        self._next_n = 0.0
        self._printed_at = -float("inf")
        super().__init__(*args, **kwargs)

    def _due(self) -> bool:
        if self.n == self._printed_n:
            return False
        if self.total:
            return self.n >= self._next_n or self.n >= self.total
        return time.monotonic() - self._printed_at >= LOG_SECONDS

    def _write_line(self) -> None:
        fmt = dict(self.format_dict)
        if not self.total:  # no percentage to give
            fmt["bar_format"] = "{desc}: {n_fmt} {unit} [{elapsed}{postfix}]"
        self.fp.write(self.format_meter(**fmt).strip() + "\n")
        getattr(self.fp, "flush", lambda: None)()
        self._printed_n, self._printed_at = self.n, time.monotonic()
        if self.total:
            step = max(self.total * self._every, 1)
            self._next_n = (self.n // step + 1) * step

    def display(self, msg: str | None = None, pos: int | None = None) -> bool:
        """Write a line when one is due (tqdm calls this on every refresh); a request to
        clear the bar (``msg=""``) writes nothing, and says so (no carriage return follows)."""
        if msg is None and self._due():
            self._write_line()
        return msg is None

    def clear(self, nolock: bool = False) -> None:
        """Nothing to clear: lines are never redrawn."""

    def close(self) -> None:
        """Write the last line (unless it was just written) and close."""
        if getattr(self, "disable", True):
            return
        if self.n != self._printed_n:
            self._write_line()
        self.leave = False  # tqdm's close then only asks to clear the line: nothing written
        super().close()


def log_progress_class() -> type[tqdm] | None:
    """:class:`LogProgress` when stderr is not a terminal, else None (tqdm's own bar): for
    libraries that take a ``tqdm_class`` (huggingface_hub)."""
    return None if is_terminal(sys.stderr) else LogProgress


def progress_bar(iterable: Iterable[Any] | None = None, *, file: TextIO | None = None,
                 every: float = LOG_EVERY, **kwargs: Any) -> tqdm:
    """A progress bar: tqdm's on a terminal, :class:`LogProgress` lines elsewhere.

    Args:
        iterable: What to iterate over, as with ``tqdm(iterable)``.
        file: Where to write; default stderr (whose being a terminal decides the kind).
        every: :class:`LogProgress`: the share of the total between two lines.
        **kwargs: tqdm's arguments (``total``, ``desc``, ``unit``, ``disable``, ``initial``,
            ``leave``...).

    Returns:
        A tqdm object.
    """
    if is_terminal(sys.stderr if file is None else file):
        from tqdm.auto import tqdm as auto_tqdm

        return auto_tqdm(iterable, file=file, **kwargs)
    return LogProgress(iterable, file=file if file is not None else sys.stderr, every=every,
                       **kwargs)
