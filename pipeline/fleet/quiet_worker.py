"""Dask worker preload of armsig's local clusters of worker processes: the worker's
process passes no other package's warning and no ``distributed`` / ``tornado`` log
record to the terminal it shares with the command (a failing task logged ``Compute
Failed`` with traceback text on every try), unless ``ARMSIG_DEBUG=1``
(:mod:`pipeline.quiet`). A process of its own: the filters stay for its life.
"""

from __future__ import annotations

from pipeline.quiet import debugging, silence_loggers, silence_warnings

if not debugging():
    silence_warnings()
    silence_loggers()
