"""What every command group shares: argument and option types, and their parsers.

The parsers turn option text into values and refuse it with one line naming the option
(an :class:`~pipeline.errors.ArmsigError`). Nothing here imports numpy (issue 18).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from pipeline.errors import ArmsigError, os_errors_refused
from pipeline.stages.base import refuse_long_names, session_path


class Method(StrEnum):
    """``ik --method``: Newton-Raphson (5.4) or Jacobi iteration (5.8)."""

    nr = "nr"
    jacobi = "jacobi"


class ExportFormat(StrEnum):
    """``export --format`` (docs/export.md)."""

    urdf = "urdf"
    dh = "dh"
    mdh = "mdh"
    json = "json"
    ur_kinematics = "ur-kinematics"
    camera_info = "camera-info"


class ExportFrame(StrEnum):
    """``export --frame`` and ``fk --frame``: the world frame of an exported chain or a pose."""

    sensor = "sensor"
    design_base = "design-base"


class Sensor(StrEnum):
    """``simulate --sensor`` (``pipeline.rig.options.SENSORS``)."""

    sonic = "sonic"
    tracker = "tracker"
    camera = "camera"


class Setup(StrEnum):
    """``simulate --setup`` (``pipeline.rig.options.SETUPS``)."""

    eye_to_hand = "eye-to-hand"
    eye_in_hand = "eye-in-hand"


class Air(StrEnum):
    """``simulate --air`` (``pipeline.rig.options.AIRS``)."""

    lab = "lab"
    drifting = "drifting"


class Fault(StrEnum):
    """The items of ``simulate --faults`` (``pipeline.rig.options.FAULTS``)."""

    bias = "bias"
    dropouts = "dropouts"
    outliers = "outliers"


class ImportFormat(StrEnum):
    """``import --format`` and ``validate --format`` (``pipeline.importers.FORMATS``)."""

    sscanss2 = "sscanss2"
    table = "table"
    rct = "rct"
    mat = "mat"
    rosbag2 = "rosbag2"
    images = "images"


class Study(StrEnum):
    """``montecarlo --study`` (``pipeline.montecarlo.studies.STUDY_NAMES``)."""

    encoder = "encoder"
    machining = "machining"
    noise = "noise"
    points = "points"
    radius = "radius"
    misalignment = "misalignment"
    features = "features"
    refine = "refine"
    compliance = "compliance"
    verdict = "verdict"
    all = "all"


class PumaBranch(StrEnum):
    """``ik --branch``: shoulder, elbow and wrist flags of a Puma solution (the labels of
    ``pipeline.robots.puma560.BRANCHES``, in their order)."""

    right_up_noflip = "right-up-noflip"
    right_up_flip = "right-up-flip"
    right_down_noflip = "right-down-noflip"
    right_down_flip = "right-down-flip"
    left_up_noflip = "left-up-noflip"
    left_up_flip = "left-up-flip"
    left_down_noflip = "left-down-noflip"
    left_down_flip = "left-down-flip"


#: Options whose value is one of an :class:`~enum.Enum`'s: any case (``--format URDF``),
#: offered by shell completion, refused with the choices (exit 2) otherwise. The enums
#: repeat the tuples of the modules doing the work (which import numpy, issue 18);
#: tests/test_cli_choices.py keeps them equal.
def choice(help_text: str, *names: str) -> Any:
    """A ``typer.Option`` taking an enum's value in any case."""
    return typer.Option(*names, help=help_text, case_sensitive=False)


def choice_list(help_text: str, enum: type[StrEnum]) -> Any:
    """A ``typer.Option`` of comma-separated values of ``enum`` (any case; ``--faults
    bias,Dropouts``): refused with the choices (exit 2) otherwise, each item offered by
    shell completion. Its value is the text; :func:`choices_of` splits it."""

    def check(text: str) -> str:
        choices_of(text, enum)
        return text

    def complete(incomplete: str) -> list[str]:
        head, _, last = incomplete.rpartition(",")
        given = {item.lower() for item in comma_list(head)}
        prefix = f"{head}," if head else ""
        return [
            prefix + e.value
            for e in enum
            if e.value.startswith(last.lower()) and e.value not in given
        ]

    return typer.Option(help=help_text, callback=check, autocompletion=complete)


def choices_of(text: str, enum: type[StrEnum]) -> tuple[str, ...]:
    """The values of ``enum`` named in comma-separated ``text`` (any case), in order; an
    unknown one is a usage error (exit 2) listing the choices."""
    values = [e.value for e in enum]
    items = comma_list(text)
    for item in items:
        if item.lower() not in values:
            listed = ", ".join(repr(v) for v in values)
            raise typer.BadParameter(f"{item!r} is not one of {listed}.")
    return tuple(item.lower() for item in items)


def optional_session_path(name: str | None) -> str | None:
    """:func:`~pipeline.stages.base.session_path` of an optional session option."""
    return None if name is None else session_path(name)


SessionArg = Annotated[
    str,
    typer.Argument(
        help="Session: a folder (sessions/robot3, ./demo) or a NAME for sessions/NAME.",
        callback=session_path,
    ),
]
#: ``--json``: machine output on stdout (warnings and errors stay on stderr).
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON on stdout for machines.")]
#: The ``NAME`` of ``simulate`` and ``import``: a new session's name or folder.
#: ``--strict`` of import and validate: refuse a row with a missing value, do not drop it.
StrictOption = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="Refuse a row with a missing or non-finite measured value (default: drop it, "
        "count it per column and say so in one line).",
    ),
]
NewSessionArg = Annotated[
    str, typer.Argument(help="Session name (sessions/NAME) or a folder path.")
]
#: ``--accept-verdict``: use a signature whose verdict is FAIL (docs/verdict.md).
AcceptVerdict = Annotated[
    bool,
    typer.Option(
        "--accept-verdict", help="Use the signature even if its verdict is FAIL (docs/verdict.md)."
    ),
]
#: ``--payload-kg``: the payload on the flange a signature's non-geometric terms predict.
PayloadOption = Annotated[
    float | None,
    typer.Option(
        help="Payload on the flange, kg: the signature's non-geometric terms predict the arm "
        "under it (docs/nongeometric.md#payload; default: the payload measured)."
    ),
]
ForceRecording = Annotated[
    bool, typer.Option(help="Replace the recording of an existing session (else refused).")
]
#: ``--robot-id`` of ``simulate`` and ``import``: the arm's own id, for ``pipeline fleet``.
RobotIdOption = Annotated[
    str | None,
    typer.Option(
        help="The arm's own id (its serial number), recorded in the session: `pipeline fleet` "
        "tells arms of one model apart by it (drift per robot id)."
    ),
]


def new_session_folder(name: str) -> Path:
    """``sessions/NAME`` for a bare name, else the folder path ``name``; a name that is
    empty or names no folder of its own (``.``, ``..``: sessions/ itself, the current
    folder or its parent) is refused in one line."""
    if Path(name).name in ("", ".", ".."):
        raise ArmsigError(
            f"session name {name!r} names no session folder of its own",
            expected="a name (sessions/NAME) or a folder path ending in a new folder's name",
            fix="pipeline simulate demo (or a path such as runs/demo)",
        )
    p = Path(name) if ("/" in name or Path(name).is_absolute()) else Path("sessions") / name
    refuse_long_names(p)
    with os_errors_refused(p, "give a folder name of at most 255 bytes"):
        if p.is_symlink() and not p.exists():  # it read "File exists" (issue 32)
            raise ArmsigError(
                f"session folder {p} is a symbolic link to {os.readlink(p)}, which does not exist",
                expected="a new folder, or a link to an existing one",
                fix="remove the link, or create the folder it points to",
            )
        if p.exists() and not p.is_dir():
            raise ArmsigError(
                f"session folder {p} is a file", expected="a new or existing session folder",
                fix="choose another name",
            )  # fmt: skip
    return p


def comma_list(text: str) -> list[str]:
    """The non-empty, stripped items of comma-separated ``text``."""
    return [item.strip() for item in text.split(",") if item.strip()]


def joint_values(text: str, option: str, example: str = '"0 -90 90 0 0 0"') -> list[float]:
    """Joint values (deg / cm), or other numbers, from a comma- or space-separated option;
    ``example``: the value its error's fix shows."""
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError as exc:
        raise ArmsigError(
            f"{option} must hold numbers", got=repr(text), fix=f"{option} {example}"
        ) from exc
    return finite(values, option)


def finite(values: Sequence[float], option: str) -> list[float]:
    """``values`` when every one is finite, else the one-line error of ``option``."""
    if not all(math.isfinite(v) for v in values):
        raise ArmsigError(
            f"{option} must hold finite numbers", got=" ".join(f"{v:g}" for v in values)
        )
    return list(values)


def stage_params(values: list[str] | None) -> dict[str, dict[str, str]]:
    """``--param STAGE.NAME=VALUE`` options as ``{stage: {name: value}}``."""
    out: dict[str, dict[str, str]] = {}
    for item in values or []:
        key, sep, value = item.partition("=")
        stage, dot, name = key.partition(".")
        if not sep or not dot:
            raise ArmsigError(
                f"--param {item!r} is not STAGE.NAME=VALUE",
                fix="--param features.plane_method=eigen",
            )
        out.setdefault(stage, {})[name] = value
    return out


#: The camera of ``simulate --sensor camera`` and ``plan --sensor camera`` (docs/camera.md),
#: and their defaults: ``pipeline.rig.options.SimulationOptions``'s (as text; equal by
#: tests/test_plan_camera.py).
RESOLUTION, FOCAL_PX, DISTORTION, PIXEL_NOISE = (
    "1280x960",
    1000.0,
    "-0.12,0.05,0.0005,-0.0003,0",
    0.2,
)
SetupOption = Annotated[
    Setup,
    choice(
        "Camera: eye-to-hand (a fixed camera watches a target on the flange) or "
        "eye-in-hand (a camera on the flange watches a fixed target)."
    ),
]
TargetFileOption = Annotated[
    str,
    typer.Option(
        "--target",
        help="Camera: target file (TOML, docs/camera.md); default a ChArUco "
        "board of 6 x 8 squares of 3.5 cm.",
    ),
]
ResolutionOption = Annotated[
    str, typer.Option("--resolution", help="Camera: image size in px, WIDTHxHEIGHT.")
]
FocalOption = Annotated[
    float,
    typer.Option("--focal-px", min=10.0, max=100000.0, help="Camera: nominal focal length (px)."),
]
DistortionOption = Annotated[
    str,
    typer.Option(
        "--distortion", help="Camera: the true lens's k1, k2, p1, p2, k3 (OpenCV's order)."
    ),
]
PixelNoiseOption = Annotated[
    float,
    typer.Option(
        "--pixel-noise", min=0.0, max=100.0, help="Camera: pixel noise σ per coordinate (px)."
    ),
]


def resolution_px(text: str) -> tuple[int, int]:
    """``--resolution WIDTHxHEIGHT`` as (width, height) px."""
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise ArmsigError("--resolution must be WIDTHxHEIGHT in px", got=repr(text),
                          fix="--resolution 1280x960")  # fmt: skip
    return int(parts[0]), int(parts[1])


def distortion_terms(text: str) -> tuple[float, float, float, float, float]:
    """``--distortion k1,k2,p1,p2,k3``: five numbers."""
    values = joint_values(text, "--distortion", "-0.12,0.05,0,0,0")
    if len(values) != 5:
        raise ArmsigError("--distortion needs five numbers: k1, k2, p1, p2, k3 (OpenCV's order)",
                          got=repr(text), fix="--distortion -0.12,0.05,0,0,0")  # fmt: skip
    k1, k2, p1, p2, k3 = values
    return k1, k2, p1, p2, k3
