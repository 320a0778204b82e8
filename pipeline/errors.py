"""The one exception hierarchy of armsig.

Every message says what was expected, what arrived, and what to try. Only
``pipeline.cli`` turns these into exit codes.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from pathlib import Path

#: The exit status of a command interrupted by Ctrl-C: 128 + SIGINT, as typer's and the
#: shells' (:mod:`pipeline.console` before the command line has loaded, ``pipeline.cli``).
EXIT_INTERRUPTED = 130


def one_line(text: str, limit: int | None = None) -> str:
    """``text`` with every run of whitespace (newlines too) as one space, cut to ``limit``
    characters (and "...") when given."""
    text = " ".join(text.split())
    return text if limit is None or len(text) <= limit else text[:limit] + "..."


class ArmsigError(Exception):
    """Base class of every error armsig raises on purpose."""

    def __init__(self, what: str, *, expected: str = "", got: str = "", fix: str = "") -> None:
        parts = [what]
        if expected:
            parts.append(f"expected {expected}")
        if got:
            parts.append(f"got {got}")
        if fix:
            parts.append(f"try: {fix}")
        super().__init__("; ".join(parts))
        self.what, self.expected, self.got, self.fix = what, expected, got, fix


class RobotDescriptionError(ArmsigError):
    """A robot description file or dict is malformed."""


class UnknownRobotError(ArmsigError):
    """A robot name is neither built in nor a readable description file."""


class SchemaError(ArmsigError):
    """A schema file is missing or malformed, or a table does not match it."""


class KinematicsError(ArmsigError):
    """Bad arguments to a kinematics routine (shapes, joint counts)."""


class FeatureError(ArmsigError):
    """Target points cannot define a feature (too few, non-finite, or degenerate)."""


class RecordingError(ArmsigError):
    """A session recording is missing, foreign, truncated, or breaks the channel contract."""


class StageError(ArmsigError):
    """A pipeline stage cannot run on its inputs (names the session and the stage)."""


class SessionLockedError(ArmsigError):
    """Another pipeline run holds the session's lock."""


class ImportFileError(ArmsigError):
    """A foreign measurement file (or its map) given to ``pipeline import`` cannot be converted."""


class VerdictFailError(ArmsigError):
    """A signature's verdict is FAIL (docs/verdict.md): ``identify`` raises it after its
    output is complete, ``export`` and ``ik`` before using the signature (unless
    ``--accept-verdict``). The command line exits 4."""


@contextlib.contextmanager
def os_errors_refused(path: str | Path, fix: str, *, always_path: bool = False) -> Iterator[None]:
    """Turn an :class:`OSError` inside the block (no space, permission, a name too long, a
    folder where a file was expected) into one line naming the path (the error's own, else
    ``path``; always ``path`` with ``always_path``, e.g. not the temp file beside it) and the
    cause, with ``fix``."""
    try:
        yield
    except OSError as exc:
        where = exc.filename if exc.filename is not None and not always_path else path
        cause = exc.strerror or one_line(str(exc), 200) or type(exc).__name__
        raise ArmsigError(f"{where}: {cause}", fix=fix) from exc


def positive_in_range(
    name: str, value: float | None, low: float = 0.0, high: float = math.inf, *,
    unit: str = "", fix: str = "",
) -> None:  # fmt: skip
    """Refuse ``value`` (None: not given, passes) unless it is a finite number above 0 and
    within [``low``, ``high``], in one line naming ``name`` (an option or a parameter)."""
    if value is None or (math.isfinite(value) and value > 0 and low <= value <= high):
        return
    u = f" {unit}" if unit else ""
    bounds = f"above 0{u}" if low <= 0 else f"at least {low:g}{u}"
    if math.isfinite(high):
        bounds += f" and at most {high:g}{u}"
    raise ArmsigError(f"{name} must be a finite number {bounds}", got=f"{value:g}", fix=fix)
