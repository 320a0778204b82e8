"""What a command writes: JSON on stdout, warnings on stderr, and the signal that a
target was not reached (exit 3, after the output). Nothing here imports numpy."""

from __future__ import annotations

import datetime
import math
from typing import Any

import typer


class NotReached(Exception):  # a signal, not an error: the output is complete
    """Raised by a command after its output when a target was not reached; the command
    group (:mod:`pipeline.cli`) turns it into exit code 3."""


def print_json(data: Any) -> None:
    """``data`` as one JSON document on stdout, for ``jq`` and scripts: every float at
    full precision (its shortest round-trip repr), NaN and infinities as ``null`` (JSON
    has none; Python's ``NaN`` token would break ``jq``), times as ISO 8601 text."""
    import json

    typer.echo(json.dumps(_jsonable(data), indent=1, allow_nan=False))


def _jsonable(data: Any) -> Any:
    """``data`` with every non-finite float replaced by None and every date-time by its
    ISO 8601 text (in dicts, lists and tuples)."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: _jsonable(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [_jsonable(v) for v in data]
    if isinstance(data, datetime.datetime):
        return data.isoformat()
    return data


def warn(text: str) -> None:
    """``warning: text`` on stderr."""
    typer.echo(f"warning: {text}", err=True)


def report(result: Any, as_json: bool, *lines: str) -> None:
    """What a command that uses a signature did: ``result.to_dict()`` as JSON (``--json``)
    or ``lines`` for people, then the signature's verdict warning when it has one."""
    if as_json:
        print_json(result.to_dict())
    else:
        for line in lines:
            typer.echo(line)
    if result.verdict_warning:
        warn(result.verdict_warning)


def warn_outside_limits(names: list[str] | tuple[str, ...]) -> None:
    """The warning for joint values outside their limits (nothing when there are none)."""
    if names:
        warn(f"outside joint limits: {', '.join(names)}")
