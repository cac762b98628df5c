"""Progress with an estimate of the remaining time, on a terminal only.

One line on stderr, rewritten in place (``\\r``) at most every ``interval`` seconds:
``simulating tyrolean_weir  41 %  3.2 s elapsed, ~4.6 s left``.  Nothing is written when the
stream is not a terminal (logs, pipes, CI) or when the ``dynsens`` logger is quieter than
WARNING (``-q``), so captured output stays clean.  The estimate is linear in the work done.
"""
from __future__ import annotations

import logging
import sys
import time
from typing import TextIO


def _fmt_seconds(s: float) -> str:
    if s < 60:
        return f"{s:.1f} s"
    m, sec = divmod(int(round(s)), 60)
    return f"{m} min {sec:02d} s" if m < 60 else f"{m // 60} h {m % 60:02d} min"


def progress_enabled(stream: TextIO | None = None) -> bool:
    """Whether progress lines go to ``stream`` (default stderr): a terminal, and not ``-q``."""
    stream = stream if stream is not None else sys.stderr
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty()) and logging.getLogger("dynsens").isEnabledFor(logging.WARNING)


class Progress:
    """A progress line for ``total`` units of work; use as a context manager.

    ``update(done, note)`` reports the units done so far (absolute, not increments).  With
    ``total=None`` (work of unknown size, e.g. SLSQP iterations) the line shows the elapsed
    time and the note only.
    """

    def __init__(self, total: float | None, label: str, stream: TextIO | None = None,
                 interval: float = 0.5, enabled: bool | None = None):
        self.total = None if total is None else max(float(total), 1e-300)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.interval = interval
        self.enabled = progress_enabled(self.stream) if enabled is None else enabled
        self.start = time.perf_counter()
        self._last = -float("inf")
        self._width = 0

    def line(self, done: float, note: str = "") -> str:
        """The text shown for ``done`` units (also used by tests)."""
        elapsed = time.perf_counter() - self.start
        if self.total is None:
            return f"{self.label}  {_fmt_seconds(elapsed)} elapsed" + (f"  {note}" if note else "")
        frac = min(max(done / self.total, 0.0), 1.0)
        left = f", ~{_fmt_seconds(elapsed * (1 - frac) / frac)} left" if 0 < frac < 1 else ""
        return f"{self.label}  {100 * frac:3.0f} %  {_fmt_seconds(elapsed)} elapsed{left}" + \
            (f"  {note}" if note else "")

    def update(self, done: float, note: str = "", force: bool = False) -> None:
        """Report progress (written at most every ``interval`` seconds unless ``force``)."""
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and now - self._last < self.interval:
            return
        self._last = now
        text = self.line(done, note)
        self.stream.write("\r" + text.ljust(self._width))
        self.stream.flush()
        self._width = len(text)

    def close(self) -> None:
        """Clear the line (the command's own output follows)."""
        if self.enabled and self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
            self._width = 0

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
