"""Robot descriptions: a frozen dataclass and its TOML file format.

The format is documented in ``schemas/robot_description.md``. Boundary units:
lengths in cm, angles in degrees; :meth:`RobotDescription.design_chain` converts
to the radians the math uses.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import RobotDescriptionError
from pipeline.kinematics.chain import SerialChain, chain_from_dh
from pipeline.kinematics.transforms import transform_from_xyz_rpy

JOINT_TYPES = ("revolute", "prismatic")


@dataclass(frozen=True)
class DHRow:
    """Design D-H parameters of one link (2.9): degrees and cm.

    For a revolute joint ``theta_deg`` is the angle at zero joint reading; for a
    prismatic joint ``d_cm`` is the distance at zero joint reading.
    """

    theta_deg: float
    d_cm: float
    a_cm: float
    alpha_deg: float


@dataclass(frozen=True)
class JointSpec:
    """One joint: its type, travel and encoder.

    ``lower``/``upper`` and ``encoder_resolution`` are in degrees for revolute
    joints and cm for prismatic joints.
    """

    name: str
    type: str
    lower: float
    upper: float
    encoder_resolution: float
    dh: DHRow

    @property
    def prismatic(self) -> bool:
        return self.type == "prismatic"

    @property
    def unit(self) -> str:
        return "cm" if self.prismatic else "deg"


@dataclass(frozen=True)
class Pose:
    """A fixed pose: position in cm, fixed-axis roll/pitch/yaw in degrees."""

    xyz_cm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """Homogeneous matrix, shape (4, 4), translation in cm."""
        return transform_from_xyz_rpy(self.xyz_cm, np.deg2rad(self.rpy_deg))


@dataclass(frozen=True)
class RobotDescription:
    """A serial robot as its maker specifies it.

    Attributes
    ----------
    name : str
    joints : tuple of JointSpec
        Base to tip.
    base : Pose
        World (mounting surface) to the D-H frame 0.
    tool : Pose
        Last D-H frame to the nominal tool frame.
    notes : str
        Free text: where the numbers come from.
    """

    name: str
    joints: tuple[JointSpec, ...]
    base: Pose = Pose()
    tool: Pose = Pose()
    notes: str = ""

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def prismatic(self) -> np.ndarray:
        """Bool mask, shape (n,)."""
        return np.array([j.prismatic for j in self.joints])

    @property
    def limits(self) -> np.ndarray:
        """Joint limits in boundary units (deg / cm), shape (n, 2)."""
        return np.array([[j.lower, j.upper] for j in self.joints], float)

    @property
    def encoder_resolution(self) -> np.ndarray:
        """Encoder resolution in boundary units (deg / cm), shape (n,)."""
        return np.array([j.encoder_resolution for j in self.joints], float)

    def design_chain(self) -> SerialChain:
        """The design model as a :class:`SerialChain` (radians, cm)."""
        rows = [j.dh for j in self.joints]
        return chain_from_dh(
            theta=np.deg2rad([r.theta_deg for r in rows]),
            d=[r.d_cm for r in rows],
            a=[r.a_cm for r in rows],
            alpha=np.deg2rad([r.alpha_deg for r in rows]),
            prismatic=self.prismatic,
            base=self.base.matrix(),
            tool=self.tool.matrix(),
        )


def _field(table: dict[str, Any], key: str, where: str, kind: type | tuple[type, ...]) -> Any:
    if key not in table:
        raise RobotDescriptionError(
            f"{where}: missing field '{key}'",
            fix="see schemas/robot_description.md for the required fields",
        )
    value = table[key]
    if kind is float:
        kind = (int, float)
    if not isinstance(value, kind) or isinstance(value, bool):
        raise RobotDescriptionError(
            f"{where}: field '{key}' has the wrong type",
            expected=getattr(kind, "__name__", "a number"),
            got=repr(value),
        )
    if isinstance(value, int | float) and not np.isfinite(value):
        raise RobotDescriptionError(
            f"{where}: field '{key}' is not a finite number", expected="a number", got=repr(value)
        )
    return value


def _known(table: dict[str, Any], allowed: tuple[str, ...], where: str) -> None:
    """Reject keys outside ``allowed``: a misspelt optional field would be ignored."""
    for key in table:
        if key not in allowed:
            raise RobotDescriptionError(
                f"{where}: unknown field '{key}'",
                expected=", ".join(allowed),
                fix="see schemas/robot_description.md",
            )


def _pose(table: dict[str, Any] | None, where: str) -> Pose:
    if table is None:
        return Pose()
    if not isinstance(table, dict):
        raise RobotDescriptionError(f"{where} is not a table", got=repr(table))
    _known(table, ("xyz_cm", "rpy_deg"), where)
    out = []
    for key in ("xyz_cm", "rpy_deg"):
        v = table.get(key, [0.0, 0.0, 0.0])
        if not (
            isinstance(v, list)
            and len(v) == 3
            and all(isinstance(x, int | float) and np.isfinite(x) for x in v)
        ):
            raise RobotDescriptionError(
                f"{where}: field '{key}' must be a list of three numbers", got=repr(v)
            )
        out.append(tuple(float(x) for x in v))
    return Pose(xyz_cm=out[0], rpy_deg=out[1])  # type: ignore[arg-type]


def description_from_dict(data: dict[str, Any], source: str = "<dict>") -> RobotDescription:
    """Validate a parsed description (the TOML document as a dict).

    Raises
    ------
    RobotDescriptionError
        Naming the source and the offending field.
    """
    _known(data, ("name", "notes", "base", "tool", "joints"), source)
    name = _field(data, "name", source, str)
    joints_raw = _field(data, "joints", source, list)
    if not joints_raw:
        raise RobotDescriptionError(f"{source}: 'joints' is empty", expected="at least one joint")
    joints: list[JointSpec] = []
    for k, jt in enumerate(joints_raw):
        where = f"{source}: joints[{k}]"
        if not isinstance(jt, dict):
            raise RobotDescriptionError(f"{where} is not a table", got=repr(jt))
        _known(jt, ("name", "type", "limits", "encoder_resolution", "dh"), where)
        jname = _field(jt, "name", where, str)
        if jname in (j.name for j in joints):
            raise RobotDescriptionError(
                f"{where}: field 'name' repeats joint name {jname!r}", expected="unique joint names"
            )
        jtype = _field(jt, "type", where, str)
        if jtype not in JOINT_TYPES:
            raise RobotDescriptionError(
                f"{where}: field 'type' is unknown",
                expected=" or ".join(JOINT_TYPES),
                got=repr(jtype),
            )
        limits = _field(jt, "limits", where, list)
        if len(limits) != 2 or not all(
            isinstance(x, int | float) and not isinstance(x, bool) and np.isfinite(x)
            for x in limits
        ):
            raise RobotDescriptionError(
                f"{where}: field 'limits' must be [lower, upper]", got=repr(limits)
            )
        if not limits[1] > limits[0]:
            raise RobotDescriptionError(
                f"{where}: field 'limits' has a negative or empty range",
                expected="lower < upper",
                got=repr(limits),
            )
        res = float(_field(jt, "encoder_resolution", where, float))
        if res <= 0:
            raise RobotDescriptionError(
                f"{where}: field 'encoder_resolution' must be positive", got=repr(res)
            )
        dh = _field(jt, "dh", where, dict)
        _known(dh, ("theta_deg", "d_cm", "a_cm", "alpha_deg"), f"{where}.dh")
        row = DHRow(
            *(
                float(_field(dh, key, f"{where}.dh", float))
                for key in ("theta_deg", "d_cm", "a_cm", "alpha_deg")
            )
        )
        joints.append(JointSpec(jname, jtype, float(limits[0]), float(limits[1]), res, row))
    return RobotDescription(
        name=name,
        joints=tuple(joints),
        base=_pose(data.get("base"), f"{source}: base"),
        tool=_pose(data.get("tool"), f"{source}: tool"),
        notes=str(data.get("notes", "")),
    )


def description_to_dict(robot: RobotDescription) -> dict[str, Any]:
    """The TOML document of ``robot`` as a dict; inverse of :func:`description_from_dict`."""
    return {
        "name": robot.name,
        "notes": robot.notes,
        "base": {"xyz_cm": list(robot.base.xyz_cm), "rpy_deg": list(robot.base.rpy_deg)},
        "tool": {"xyz_cm": list(robot.tool.xyz_cm), "rpy_deg": list(robot.tool.rpy_deg)},
        "joints": [
            {
                "name": j.name,
                "type": j.type,
                "limits": [j.lower, j.upper],
                "encoder_resolution": j.encoder_resolution,
                "dh": {
                    "theta_deg": j.dh.theta_deg,
                    "d_cm": j.dh.d_cm,
                    "a_cm": j.dh.a_cm,
                    "alpha_deg": j.dh.alpha_deg,
                },
            }
            for j in robot.joints
        ],
    }


def load_description(path: str | Path) -> RobotDescription:
    """Read and validate a TOML robot description file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise RobotDescriptionError(
            f"cannot read robot description {p}", got=str(exc), fix="check the path"
        ) from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RobotDescriptionError(f"{p}: not valid TOML", got=str(exc)) from exc
    return description_from_dict(data, source=str(p))
