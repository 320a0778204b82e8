"""Robot descriptions: a frozen dataclass and its TOML file format.

The format is documented in ``schemas/robot_description.md``. Boundary units:
lengths in cm, angles in degrees; :meth:`RobotDescription.design_chain` converts
to the radians the math uses.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.errors import RobotDescriptionError, one_line

if TYPE_CHECKING:  # the kinematics are imported where a chain or pose is built
    from pipeline.kinematics.chain import SerialChain

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
    joints and cm for prismatic joints; ``velocity_limit`` in deg/s or cm/s and
    ``effort_limit`` in N·m or N, None when the description does not give them (only
    exports use them: the URDF's ``<limit>``).
    """

    name: str
    type: str
    lower: float
    upper: float
    encoder_resolution: float
    dh: DHRow
    velocity_limit: float | None = None
    effort_limit: float | None = None

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
        from pipeline.kinematics.transforms import transform_from_xyz_rpy

        return transform_from_xyz_rpy(self.xyz_cm, np.deg2rad(self.rpy_deg))


@dataclass(frozen=True)
class Coupling:
    """Linear joint coupling: joint = C · reading + offset (boundary units, deg / cm).

    Controllers of coupled axes report readings, not joint values (FANUC: physical
    J3 = reading J3 + reading J2). ``matrix`` is C, shape (n, n), invertible;
    ``offset`` shape (n,).
    """

    matrix: tuple[tuple[float, ...], ...]
    offset: tuple[float, ...]

    def joints(self, readings: np.ndarray) -> np.ndarray:
        """Joint values (..., n) of readings (..., n)."""
        return np.asarray(readings, float) @ np.array(self.matrix).T + np.array(self.offset)

    def readings(self, joints: np.ndarray) -> np.ndarray:
        """Readings (..., n) that give joint values (..., n): C⁻¹ (joint − offset)."""
        c = np.array(self.matrix)
        return np.linalg.solve(c, (np.asarray(joints, float) - np.array(self.offset)).T).T


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
    coupling : Coupling, optional
        How the controller's readings give joint values; None: they are the joint values.
    """

    name: str
    joints: tuple[JointSpec, ...]
    base: Pose = Pose()
    tool: Pose = Pose()
    notes: str = ""
    coupling: Coupling | None = None

    @property
    def reach_cm(self) -> float:
        """The design's size (cm): every D-H length |a| and |d|, a prismatic joint's
        farthest travel and the tool's offset, summed; the base pose is left out (the
        verdict's design alignment absorbs it). The verdict's plausibility scale."""
        total = float(np.linalg.norm(self.tool.xyz_cm))
        for j in self.joints:
            travel = max(abs(j.lower), abs(j.upper)) if j.prismatic else 0.0
            total += abs(j.dh.a_cm) + abs(j.dh.d_cm) + travel
        return total

    def joints_from_readings(self, readings: np.ndarray) -> np.ndarray:
        """Joint values (..., n) of controller readings (..., n), deg / cm."""
        q = np.asarray(readings, float)
        return q if self.coupling is None else self.coupling.joints(q)

    def readings_from_joints(self, joints: np.ndarray) -> np.ndarray:
        """Controller readings (..., n) that give joint values (..., n), deg / cm."""
        q = np.asarray(joints, float)
        return q if self.coupling is None else self.coupling.readings(q)

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

    def random_configurations(self, m: int, seed: int) -> np.ndarray:
        """``m`` joint values (m, n) drawn uniformly within the limits by a generator seeded
        with ``seed``, internal units (rad / cm): the configurations the audit, the
        predicted accuracy, the design alignment and the pose planner average over."""
        from pipeline.units import joints_to_internal

        lim = self.limits
        q = np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (m, self.n_joints))
        return np.asarray(joints_to_internal(q, self.prismatic), float)

    def design_chain(self) -> SerialChain:
        """The design model as a :class:`SerialChain` (radians, cm)."""
        from pipeline.kinematics.chain import chain_from_dh

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


#: Bounds of a description. Two turns either way covers any revolute joint (and any
#: angle of the D-H rows and poses); 10 m covers any arm and prismatic travel. They
#: keep the planner's joint grids (2°/1 cm, then 0.5°/0.1 cm steps over the travel)
#: and every later array to a size that fits in memory.
MAX_JOINTS = 12
MAX_ANGLE_DEG = 720.0
MAX_LENGTH_CM = 1000.0
#: A coupling matrix must be this well conditioned: readings carry about 7 significant
#: digits (1e-5 deg of 180 deg), so a condition number of 1e6 still resolves joint
#: values to about 0.1 deg; a worse C is a typo or a singular map, not a controller.
MAX_COUPLING_COND = 1e6
#: Bounds of the optional velocity (deg/s, cm/s) and effort (N·m, N) limits: far above
#: any arm (a fast robot turns ~1,000 deg/s; a large one's base ~10⁵ N·m), they only
#: catch a typo or a unit off by 10⁶.
MAX_VELOCITY = 1e5
MAX_EFFORT = 1e7
#: The optional per-joint fields and their bounds (value, unit for the message).
_RATES = (
    ("velocity_limit", MAX_VELOCITY, "deg/s or cm/s"),
    ("effort_limit", MAX_EFFORT, "N·m or N"),
)


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _bounded(value: Any, key: str, where: str, bound: float, unit: str) -> float:
    """``value`` as a float when it is a finite number within ±``bound`` ``unit``."""
    if not _is_number(value):
        raise RobotDescriptionError(
            f"{where}: field '{key}' has the wrong type", expected="a number", got=repr(value)
        )
    if not np.isfinite(value):
        raise RobotDescriptionError(
            f"{where}: field '{key}' is not a finite number", expected="a number", got=repr(value)
        )
    if abs(value) > bound:
        raise RobotDescriptionError(
            f"{where}: field '{key}' is out of bounds",
            expected=f"within ±{bound:g} {unit}",
            got=repr(value),
        )
    return float(value)


_KINDS: dict[type, str] = {str: "a string", list: "a list", dict: "a table"}


def _field(table: dict[str, Any], key: str, where: str, kind: type) -> Any:
    if key not in table:
        raise RobotDescriptionError(
            f"{where}: missing field '{key}'",
            fix="see schemas/robot_description.md for the required fields",
        )
    value = table[key]
    if not isinstance(value, kind):
        raise RobotDescriptionError(
            f"{where}: field '{key}' has the wrong type",
            expected=_KINDS.get(kind, kind.__name__),
            got=repr(value),
        )
    return value


def _name(table: dict[str, Any], key: str, where: str) -> str:
    """A name field: a non-empty printable string without surrounding spaces, commas or
    ``=`` (names key the signature, the URDF's links and ``--joint-map a=b,c=d``)."""
    value: str = _field(table, key, where, str)
    if not value or value != value.strip() or not value.isprintable() or set(value) & {",", "="}:
        raise RobotDescriptionError(
            f"{where}: field '{key}' is not a usable name",
            expected="a non-empty name without surrounding spaces, control characters, ',' or '='",
            got=repr(value),
            fix='e.g. name = "shoulder"',
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


def _pose(table: Any, where: str) -> Pose:
    if table is None:
        return Pose()
    if not isinstance(table, dict):
        raise RobotDescriptionError(f"{where} is not a table", got=repr(table))
    _known(table, ("xyz_cm", "rpy_deg"), where)
    out = []
    for key, bound, unit in (("xyz_cm", MAX_LENGTH_CM, "cm"), ("rpy_deg", MAX_ANGLE_DEG, "deg")):
        v = table.get(key, [0.0, 0.0, 0.0])
        if not (isinstance(v, list) and len(v) == 3):
            raise RobotDescriptionError(
                f"{where}: field '{key}' must be a list of three numbers", got=repr(v)
            )
        out.append(tuple(_bounded(x, key, where, bound, unit) for x in v))
    return Pose(xyz_cm=out[0], rpy_deg=out[1])  # type: ignore[arg-type]


def _joint(jt: Any, where: str) -> JointSpec:
    """One ``[[joints]]`` table; travel and lengths within the bounds of a description."""
    if not isinstance(jt, dict):
        raise RobotDescriptionError(f"{where} is not a table", got=repr(jt))
    _known(jt, ("name", "type", "limits", "encoder_resolution", "dh", *(k for k, *_ in _RATES)),
           where)  # fmt: skip
    jname = _name(jt, "name", where)
    jtype = _field(jt, "type", where, str)
    if jtype not in JOINT_TYPES:
        raise RobotDescriptionError(
            f"{where}: field 'type' is unknown", expected=" or ".join(JOINT_TYPES), got=repr(jtype)
        )
    bound, unit = (MAX_LENGTH_CM, "cm") if jtype == "prismatic" else (MAX_ANGLE_DEG, "deg")
    limits = _field(jt, "limits", where, list)
    if len(limits) != 2:
        raise RobotDescriptionError(
            f"{where}: field 'limits' must be [lower, upper]", got=repr(limits)
        )
    lower, upper = (_bounded(x, "limits", where, bound, f"{unit} ({jtype})") for x in limits)
    if not upper > lower:
        raise RobotDescriptionError(
            f"{where}: field 'limits' has a negative or empty range",
            expected="lower < upper",
            got=repr(limits),
        )
    res = _bounded(_field(jt, "encoder_resolution", where, object), "encoder_resolution",
                   where, upper - lower, f"{unit} (the travel)")  # fmt: skip
    if res <= 0:
        raise RobotDescriptionError(
            f"{where}: field 'encoder_resolution' must be positive", got=repr(res)
        )
    dh = _field(jt, "dh", where, dict)
    _known(dh, ("theta_deg", "d_cm", "a_cm", "alpha_deg"), f"{where}.dh")
    row = DHRow(
        *(
            _bounded(_field(dh, key, f"{where}.dh", object), key, f"{where}.dh", *b)
            for key, b in (
                ("theta_deg", (MAX_ANGLE_DEG, "deg")),
                ("d_cm", (MAX_LENGTH_CM, "cm")),
                ("a_cm", (MAX_LENGTH_CM, "cm")),
                ("alpha_deg", (MAX_ANGLE_DEG, "deg")),
            )
        )
    )
    rates = [None if jt.get(k) is None else _bounded(jt[k], k, where, b, u) for k, b, u in _RATES]
    for (key, *_), v in zip(_RATES, rates, strict=True):
        if v is not None and v <= 0:
            raise RobotDescriptionError(f"{where}: field '{key}' must be positive", got=repr(v))
    return JointSpec(jname, jtype, lower, upper, res, row, *rates)


def _coupling(table: Any, n: int, where: str) -> Coupling | None:
    """The optional ``[coupling]`` table: ``matrix`` n x n, invertible; ``offset`` n."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise RobotDescriptionError(f"{where} is not a table", got=repr(table))
    _known(table, ("matrix", "offset"), where)
    matrix = _field(table, "matrix", where, list)
    if len(matrix) != n or any(not isinstance(r, list) or len(r) != n for r in matrix):
        raise RobotDescriptionError(
            f"{where}: field 'matrix' must be {n} rows of {n} numbers (one per joint)",
            got=repr(matrix)[:120],
        )
    c = tuple(tuple(_bounded(x, "matrix", where, 1e3, "") for x in r) for r in matrix)
    offset = table.get("offset", [0.0] * n)
    if not isinstance(offset, list) or len(offset) != n:
        raise RobotDescriptionError(
            f"{where}: field 'offset' must be a list of {n} numbers", got=repr(offset)[:120]
        )
    off = tuple(_bounded(x, "offset", where, MAX_ANGLE_DEG, "deg or cm") for x in offset)
    cond = float(np.linalg.cond(np.array(c)))
    if not cond < MAX_COUPLING_COND:
        raise RobotDescriptionError(
            f"{where}: field 'matrix' is not invertible",
            expected=f"a condition number below {MAX_COUPLING_COND:g}",
            got=f"{cond:.3g}",
            fix="joint = matrix · reading + offset; check the matrix rows",
        )
    return Coupling(c, off)


def description_from_dict(data: Any, source: str = "<dict>") -> RobotDescription:
    """Validate a parsed description (the TOML document as a dict).

    Raises
    ------
    RobotDescriptionError
        Naming the source and the offending field.
    """
    if not isinstance(data, dict):
        raise RobotDescriptionError(f"{source} is not a table", got=repr(data)[:80])
    from pipeline.robots.conventions import standard_form

    data = standard_form(data, source)  # modified D-H rows, fixed rows (issue 42)
    _known(data, ("name", "notes", "base", "tool", "joints", "coupling"), source)
    name = _name(data, "name", source)
    notes = data.get("notes", "")
    if not isinstance(notes, str):
        raise RobotDescriptionError(
            f"{source}: field 'notes' has the wrong type", expected="a string", got=repr(notes)
        )
    joints_raw = _field(data, "joints", source, list)
    if not 1 <= len(joints_raw) <= MAX_JOINTS:
        raise RobotDescriptionError(
            f"{source}: field 'joints' holds {len(joints_raw)} joints",
            expected=f"1 to {MAX_JOINTS} joints",
        )
    joints: list[JointSpec] = []
    for k, jt in enumerate(joints_raw):
        joint = _joint(jt, f"{source}: joints[{k}]")
        if joint.name in (j.name for j in joints):
            raise RobotDescriptionError(
                f"{source}: joints[{k}]: field 'name' repeats joint name {joint.name!r}",
                expected="unique joint names",
            )
        joints.append(joint)
    return RobotDescription(
        name=name,
        joints=tuple(joints),
        base=_pose(data.get("base"), f"{source}: base"),
        tool=_pose(data.get("tool"), f"{source}: tool"),
        notes=notes,
        coupling=_coupling(data.get("coupling"), len(joints), f"{source}: coupling"),
    )


def description_to_dict(robot: RobotDescription) -> dict[str, Any]:
    """The TOML document of ``robot`` as a dict; inverse of :func:`description_from_dict`."""
    coupling = robot.coupling
    extra = (
        {}
        if coupling is None
        else {"coupling": {"matrix": [list(r) for r in coupling.matrix],
                           "offset": list(coupling.offset)}}
    )  # fmt: skip
    return {
        **extra,
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
                **{k: getattr(j, k) for k, *_ in _RATES if getattr(j, k) is not None},
            }
            for j in robot.joints
        ],
    }


def load_description(path: str | Path) -> RobotDescription:
    """Read and validate a TOML robot description file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotDescriptionError(
            f"cannot read robot description {p}", got=one_line(str(exc), 200),
            fix="check the path; the file must be UTF-8 text",
        ) from exc  # fmt: skip
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:  # RecursionError: nested deep
        raise RobotDescriptionError(f"{p}: not valid TOML", got=one_line(str(exc), 200)) from exc
    return description_from_dict(data, source=str(p))
