"""``python -m pipeline``: the same command line as ``pipeline`` (same exit codes)."""

from pipeline.cli import app

app(prog_name="pipeline")
