"""What a command writes: JSON on stdout, warnings on stderr, and the signal that a
target was not reached (exit 3, after the output). Nothing here imports numpy."""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator
from typing import Any

import typer


class NotReached(Exception):  # a signal, not an error: the output is complete
    """Raised by a command after its output when a target was not reached; the command
    group (:mod:`pipeline.cli`) turns it into exit code 3."""


def print_json(data: Any) -> None:
    """``data`` as JSON on stdout, for ``jq`` and scripts."""
    import json

    typer.echo(json.dumps(data, indent=1))


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


@contextlib.contextmanager
def quiet_numpy(debug: bool) -> Iterator[None]:
    """No numpy floating-point or RuntimeWarning lines on stderr (unless ``debug``).

    armsig checks its numbers itself (finite inputs, dropouts as NaN, feature
    checks) and reports what matters as warnings of its own or as an error, so
    numpy's ``invalid value`` / ``divide by zero`` / ``Mean of empty slice`` lines
    would only precede those. They are all RuntimeWarnings (numpy's default error
    state warns), so the filter silences them without importing numpy: a warm
    ``identify`` needs none (issue 18). Other warning categories still print.
    """
    if debug:
        yield
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield
