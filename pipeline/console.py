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
"""

from __future__ import annotations

import os


def main() -> None:
    """Run the command line (typer's exit codes)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from pipeline.cli import app

    app(prog_name="pipeline")
