"""The one progress line of long commands (``identify``, ``evaluate``, ``montecarlo``,
``fleet``) on stderr: ``label  [#####.....]  12/40 batches  35.0 s  ETA 1 min 17 s``,
redrawn with ``\\r`` on a terminal; elsewhere (a log file, a pipe) only the final line,
as a summary (without an ETA)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

#: The ETA is shown once this much time has passed (s): the first steps' pace says
#: little (imports, kernel caches) and a short run needs none.
ETA_AFTER_S = 1.0


def format_eta(seconds: float) -> str:
    """``ETA 42 s``, ``ETA 3 min 05 s``, ``ETA 2 h 07 min`` (rounded up to the unit shown)."""
    s = max(0, int(-(-seconds // 1)))  # whole seconds, rounded up
    if s < 60:
        return f"ETA {s} s"
    if s < 3600:
        return f"ETA {s // 60} min {s % 60:02d} s"
    m = -(-s // 60)
    return f"ETA {m // 60} h {m % 60:02d} min"


def eta_seconds(done: int, total: int, elapsed: float) -> float | None:
    """Remaining time at the pace so far, ``elapsed / done`` per step; None before a
    step is done or :data:`ETA_AFTER_S` has passed, and once all are done."""
    if done < 1 or done >= total or elapsed < ETA_AFTER_S:
        return None
    return elapsed / done * (total - done)


class Progress:
    """A one-line progress bar over ``total`` steps of ``unit`` (None stream: silent);
    ``clock``: seconds (tests inject one)."""

    def __init__(
        self,
        label: str,
        total: int,
        stream: TextIO | None = sys.stderr,
        unit: str = "batches",
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.label, self.total, self.stream, self.unit = label, total, stream, unit
        self.clock = clock
        self.done = 0
        self.drawn = 0  # characters of the line on a terminal, blanked by a shorter one
        self.t0 = clock()

    def line(self) -> str:
        """The line as drawn now (without ``\\r`` and newline)."""
        width = 30
        fill = int(width * self.done / max(self.total, 1))
        elapsed = self.clock() - self.t0
        eta = eta_seconds(self.done, self.total, elapsed)
        return (
            f"{self.label:14s} [{'#' * fill}{'.' * (width - fill)}] "
            f"{self.done}/{self.total} {self.unit} {elapsed:6.1f} s"
            + ("" if eta is None else f"  {format_eta(eta)}")
        )

    def step(self) -> None:
        self.done += 1
        if self.stream is None:
            return
        last, tty = self.done >= self.total, self.stream.isatty()
        if not last and not tty:  # a log file gets the final line only
            return
        text = self.line()
        if tty:  # over the previous line: blank what a longer one left
            text, self.drawn = "\r" + text.ljust(self.drawn), len(text)
        self.stream.write(text + ("\n" if last else ""))
        self.stream.flush()

    def close(self) -> None:
        """End a line left unfinished on a terminal (a run stopped early by an error),
        so that the error message starts on a line of its own."""
        if self.stream is not None and 0 < self.done < self.total and self.stream.isatty():
            self.stream.write("\n")
            self.stream.flush()
