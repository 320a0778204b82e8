"""``python -m pipeline.cli``: the command line (``python -m pipeline`` also sets the
BLAS threads first: :mod:`pipeline.console`)."""

from pipeline.cli import app

app()
