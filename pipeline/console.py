"""The ``pipeline`` console script and ``python -m pipeline``: the command line of
:mod:`pipeline.cli`, started with one OpenBLAS thread unless the user says otherwise.

numpy and scipy each load their own OpenBLAS, and each starts a pool of one thread per
core whose idle threads spin: on this 2-core machine
``import numpy, scipy.linalg, scipy.sparse`` took 0.46-0.62 s of CPU against 0.28-0.29 s
with ``OPENBLAS_NUM_THREADS=1`` (docs/scale.md). The command line has no use for the
pool: every stage computes on one BLAS thread anyway
(:func:`pipeline.stages.runner.one_blas_thread`, for the same bits on every machine), and
batched control runs on numba's threads. The variable must be set before numpy loads, so
here, before :mod:`pipeline.cli` is imported; a value already in the environment wins.
Ctrl-C while it loads ends the command with status 130 and no traceback.
"""

from __future__ import annotations

import os
import signal
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from types import FrameType


def _interrupted(signum: int, frame: FrameType | None) -> None:
    """Ctrl-C: the status of an interrupted command, never a traceback (issue 44: one came
    from an import in the first ~0.5 s, while the command line loads). A SystemExit runs
    the ``finally`` blocks and context managers (temp files removed, locks released) as a
    KeyboardInterrupt does. (This module imports only ``os`` and ``signal``: it is loaded
    before the handler is installed.)"""
    from pipeline.errors import EXIT_INTERRUPTED

    raise SystemExit(EXIT_INTERRUPTED)


def main() -> None:
    """Run the command line (typer's exit codes; Ctrl-C: 130, no traceback)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    signal.signal(signal.SIGINT, _interrupted)  # before the imports of the command line
    from pipeline.cli import app

    app(prog_name="pipeline")
