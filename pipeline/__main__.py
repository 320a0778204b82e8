"""``python -m pipeline``: the same command line as ``pipeline`` (same exit codes)."""

from pipeline.console import main

main()
