"""The one progress line of long commands (``identify``, ``evaluate``, ``montecarlo``) on
stderr: ``label  [#####.....]  12/40 batches  35 s``, redrawn with ``\\r`` on a terminal;
elsewhere (a log file, a pipe) only the final line, as a summary."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """A one-line progress bar over ``total`` steps of ``unit`` (None stream: silent)."""

    def __init__(
        self, label: str, total: int, stream: TextIO | None = sys.stderr, unit: str = "batches"
    ) -> None:
        self.label, self.total, self.stream, self.unit = label, total, stream, unit
        self.done = 0
        self.t0 = time.perf_counter()

    def step(self) -> None:
        self.done += 1
        if self.stream is None:
            return
        last, tty = self.done >= self.total, self.stream.isatty()
        if not last and not tty:  # a log file gets the final line only
            return
        width = 30
        fill = int(width * self.done / max(self.total, 1))
        start, end = "\r" if tty else "", "\n" if last else ""
        self.stream.write(
            f"{start}{self.label:14s} [{'#' * fill}{'.' * (width - fill)}] "
            f"{self.done}/{self.total} {self.unit} {time.perf_counter() - self.t0:6.1f} s{end}"
        )
        self.stream.flush()

    def close(self) -> None:
        """End a line left unfinished on a terminal (a run stopped early by an error),
        so that the error message starts on a line of its own."""
        if self.stream is not None and 0 < self.done < self.total and self.stream.isatty():
            self.stream.write("\n")
            self.stream.flush()
