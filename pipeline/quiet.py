"""Other packages' chatter kept off the user's terminal, unless ``ARMSIG_DEBUG=1``.

armsig says what matters itself, in one line (a warning of its own or an error), so a
command prints no Python warning from another package, no numpy ``RuntimeWarning`` (it
checks its numbers itself) and no log record of Dask's ``distributed``, ``tornado`` or
``bokeh``: ``fleet`` printed 25 lines of ``distributed.worker - ERROR - Compute Failed``
with traceback text for one failing session (issue 30 item 6, issue 32). With
``ARMSIG_DEBUG=1`` they all print as their packages decide. Nothing here imports numpy.
"""

from __future__ import annotations

import contextlib
import logging
import os
import warnings
from collections.abc import Iterator

#: The environment variable that shows tracebacks and other packages' warnings and logs.
DEBUG_ENV = "ARMSIG_DEBUG"
#: Loggers silenced (and their children): Dask's, and the libraries its servers use.
LOGGERS = ("distributed", "tornado", "bokeh", "asyncio")
#: Above every level: a silenced logger passes no record, CRITICAL included.
SILENT = logging.CRITICAL + 1
#: A warning attributed to any module but armsig's (``warnings.filterwarnings``'s regex,
#: matched at the start of the module name).
OTHER_MODULES = r"(?!pipeline(\.|$))"


def debugging() -> bool:
    """``ARMSIG_DEBUG=1`` in the environment (worker processes inherit it)."""
    return os.environ.get(DEBUG_ENV) == "1"


def silence_warnings() -> None:
    """Ignore, from here on, numpy's ``RuntimeWarning`` (armsig checks its numbers: finite
    inputs, dropouts as NaN, feature checks) and every warning of another package.
    armsig's own categories still print. Scope it with ``warnings.catch_warnings``."""
    warnings.simplefilter("ignore", RuntimeWarning)
    warnings.filterwarnings("ignore", module=OTHER_MODULES)


def silence_loggers() -> dict[logging.Logger, int]:
    """Set :data:`LOGGERS` and every existing child to :data:`SILENT` (children made later
    inherit it); returns their previous levels for :func:`restore_loggers`."""
    names = {*LOGGERS, *(n for n in logging.root.manager.loggerDict if n.split(".")[0] in LOGGERS)}
    saved = {}
    for name in sorted(names):
        logger = logging.getLogger(name)
        saved[logger] = logger.level
        logger.setLevel(SILENT)
    return saved


def restore_loggers(saved: dict[logging.Logger, int]) -> None:
    for logger, level in saved.items():
        logger.setLevel(level)


@contextlib.contextmanager
def quiet(debug: bool | None = None) -> Iterator[None]:
    """No other package's warnings or Dask's log records inside the block, unless
    ``debug`` (default: :func:`debugging`). Warnings armsig's checks turn into its own
    lines (numpy's ``invalid value``, ``Mean of empty slice``) would only precede them."""
    if debugging() if debug is None else debug:
        yield
        return
    with warnings.catch_warnings():
        silence_warnings()
        saved = silence_loggers()
        try:
            yield
        finally:
            restore_loggers(saved)
