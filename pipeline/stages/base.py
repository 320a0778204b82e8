"""The stage contract: a name, a version, inputs, frozen parameters, one output schema.

A stage's ``compute`` is a pure function of its inputs (stage tables, or the
parsed recording for the extract stages) and its parameters.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pipeline.errors import ArmsigError, StageError, one_line

if TYPE_CHECKING:
    import pyarrow as pa

RECORDING = "recording"
#: The images a recording references by content hash (``/camera/images``, issue 40): a
#: stage input hashed from the image files themselves (:mod:`pipeline.stages.image_inputs`).
IMAGES = "images"


#: The longest name of one folder or file (bytes): Linux's NAME_MAX, and most file systems'.
NAME_MAX = 255


def refuse_long_names(path: str | Path) -> None:
    """Refuse, in one line, a path with a part over :data:`NAME_MAX` bytes (its ``stat``
    raised "File name too long" as an internal error in every session command, issue 44)."""
    long = [part for part in Path(path).parts if len(os.fsencode(part)) > NAME_MAX]
    if long:
        raise ArmsigError(
            f"session {one_line(str(path), 80)}: File name too long (a name of "
            f"{len(os.fsencode(long[0]))} bytes)",
            expected=f"names of at most {NAME_MAX} bytes (the file system's limit)",
            fix="give the session's folder or NAME (pipeline status sessions/robot3)",
        )


def session_path(name: str) -> str:
    """A session argument as ``simulate`` and ``import`` name it (issue 30): a folder path as
    given; a bare NAME (no ``/``) that is not a folder here names ``sessions/NAME`` when that
    is one, so ``pipeline simulate robot8`` then ``pipeline identify robot8`` is one session."""
    refuse_long_names(name)
    if "/" in name or Path(name).is_absolute() or Path(name).is_dir():
        return name
    under = Path("sessions") / name
    return str(under) if under.is_dir() else name


def session_or_robot(name: str) -> str:
    """``fk``'s argument: a built-in robot's name as it is, else a session argument
    (:func:`pipeline.stages.base.session_path`: a NAME may name ``sessions/NAME``)."""
    from pipeline.robots import builtin_names

    return name if name in builtin_names() else session_path(name)


def _no_folder(sdir: Path) -> str:
    bare = len(sdir.parts) == 1 and not sdir.is_absolute()
    return f" (no folder {sdir} here, nor sessions/{sdir})" if bare else " (no such folder)"


def session_folder(session_dir: str | Path) -> Path:
    """``session_dir`` as a Path, refused with one line unless it holds a recording."""
    sdir = Path(session_dir)
    refuse_long_names(sdir)
    if not (sdir / "recording.mcap").is_file():
        raise StageError(
            f"{sdir}: no recording.mcap" + ("" if sdir.is_dir() else _no_folder(sdir)),
            expected="a session folder holding recording.mcap",
            fix="`pipeline simulate NAME` records a simulated session",
        )
    return sdir


def check_param(params: Any, stage: str, name: str, ok: bool, rule: str) -> None:
    """Raise the one-line error of a stage parameter that breaks its ``rule`` (unless ``ok``).

    Called from the ``__post_init__`` of a stage's ``Params``, so a bad ``--param``
    is refused where it enters, naming the parameter and its default.
    """
    if ok:
        return
    default = next(f.default for f in dataclasses.fields(params) if f.name == name)
    raise ArmsigError(
        f"parameter {stage}.{name} must be {rule}",
        got=_text(getattr(params, name)),
        fix=f"--param {stage}.{name}={default:g} (the default)"
        if isinstance(default, float)
        else f"--param {stage}.{name}={default} (the default)",
    )


def _text(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else repr(value)


@dataclass(frozen=True)
class NoParams:
    """For stages without parameters."""


@dataclass(frozen=True)
class Stage:
    """One pipeline stage.

    Attributes
    ----------
    name : str
        Output file ``stages/<name>.arrow``; also the schema name in ``schemas/arrow``.
    version : int
        Bump when the computation changes: cached outputs become stale.
    inputs : tuple of str
        ``"recording"`` or names of earlier stages.
    params : frozen dataclass instance
        Default parameters.
    compute : callable
        ``compute(inputs, params) -> pa.Table``.
    summary : str
        One line for ``pipeline status``.
    """

    name: str
    version: int
    inputs: tuple[str, ...]
    params: Any
    compute: Callable[[Mapping[str, Any], Any], pa.Table]
    summary: str

    def params_dict(self, params: Any | None = None) -> dict[str, Any]:
        return dataclasses.asdict(params if params is not None else self.params)


@dataclass(frozen=True)
class StageRun:
    """What the runner did with one stage: ``ran`` or ``cached``, and how long it took
    (``seconds`` wall, ``cpu_seconds`` this process's CPU: user + system, all threads)."""

    name: str
    action: str
    seconds: float
    rows: int
    cpu_seconds: float = 0.0
