"""Poses and joints in boundary units (cm, deg): the work of ``pipeline fk`` and
``pipeline ik``, for tests and notebooks too.

- :func:`tool_pose`: the tool pose at joint readings, of a session's signature or of a
  robot's design model; :func:`poses_of_file`: the same for a file of configurations;
- :func:`solve_pose`: the joint readings that put a session's tool at one pose;
- :func:`solve_targets`: an Arrow file of poses solved into an Arrow file of joints.

Refused input raises an :class:`~pipeline.errors.ArmsigError`; a target that is not
reached is an answer (``converged`` false), not an error.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.robots.description import RobotDescription
from pipeline.robots.fk import ToolPose, ToolPoses

if TYPE_CHECKING:
    from pipeline.control.controller import Controller

#: ``fk``'s world frame by default: the design base frame, what ``ik --pose`` takes back.
DEFAULT_FRAME = "design-base"


def tool_pose(
    robot: str | Path,
    q: Sequence[float],
    design: bool = False,
    payload_kg: float | None = None,
    frame: str = DEFAULT_FRAME,
) -> ToolPose:
    """The tool pose at joint readings ``q`` (n,), deg / cm.

    ``robot``: an identified session folder (the pose of its signature's tool in
    ``frame``: the design base frame, what :func:`solve_pose` takes back, or the sensor
    frame, the model's prediction of a measured point; under ``payload_kg`` when given
    (:meth:`Controller.with_payload`); ``design``: the design model's pose of that tool),
    else a built-in robot name or a ``.toml`` description (the pose of its design tool
    frame, the last D-H frame times the description's ``[tool]``, in its base frame).
    """
    model = _pose_model(robot, payload_kg)
    if not isinstance(model, RobotDescription):
        return model.pose(list(q), design=design, frame=frame)  # type: ignore[no-any-return]
    _session_options(payload_kg, frame)
    from pipeline.robots.fk import design_pose

    return design_pose(model, list(q))


def payload_warning(robot: str | Path, payload_kg: float | None) -> str | None:
    """The warning for a ``payload_kg`` outside the payloads the session ``robot``
    measured (:meth:`~pipeline.kinematics.nongeometric.NonGeometric.payload_extrapolated`;
    None without one, or for a robot description)."""
    if payload_kg is None:
        return None
    model = _pose_model(robot, payload_kg)
    return None if isinstance(model, RobotDescription) else model.payload_warning


def _session_options(payload_kg: float | None, frame: str) -> None:
    """Refuse the options only a session has, given with a robot description."""
    if payload_kg is not None:
        raise ArmsigError("--payload-kg needs an identified session", fix="give a session folder")
    if frame != DEFAULT_FRAME:
        raise ArmsigError(
            f"--frame {frame} needs an identified session (a robot description has no sensor)",
            fix="give a session folder, or drop --frame",
        )


def _pose_model(robot: str | Path, payload_kg: float | None = None) -> Any:
    """What :func:`tool_pose` evaluates: a session's controller (a folder, or a NAME of
    ``sessions/NAME`` that is no built-in robot) under ``payload_kg`` when given
    (:meth:`Controller.with_payload`), else the robot description."""
    from pipeline.stages.base import session_or_robot

    robot = session_or_robot(str(robot))
    if Path(robot).is_dir():
        from pipeline.control.session import session_controller

        ctl = session_controller(robot)
        return ctl if payload_kg is None else ctl.with_payload(payload_kg)
    from pipeline.robots import get_robot

    return get_robot(str(robot))


@dataclass(frozen=True)
class PosesFile:
    """What :func:`poses_of_file` computed: the configurations' robot, joint readings
    (m, n), poses, and the file written (None: none)."""

    robot: str
    joints: tuple[str, ...]
    q: np.ndarray
    poses: ToolPoses
    out: str | None
    frame: str = DEFAULT_FRAME

    def to_dict(self) -> dict[str, Any]:
        """Every pose at full precision (``fk --q-file --json``)."""
        p = self.poses
        return {
            "robot": self.robot,
            "joints": list(self.joints),
            "out": self.out,
            "frame": self.frame,
            "poses": [
                {
                    "q": self.q[k].tolist(),
                    "xyz_cm": p.xyz_cm[k].tolist(),
                    "rpy_deg": p.rpy_deg[k].tolist(),
                    "matrix": p.matrix[k].tolist(),
                    "outside_limits": list(p.outside_limits[k]),
                }
                for k in range(len(self.q))
            ],
        }


def poses_of_file(
    robot: str | Path,
    q_file: str | Path,
    *,
    design: bool = False,
    out: str | Path | None = None,
    force: bool = False,
    frame: str = DEFAULT_FRAME,
    payload_kg: float | None = None,
) -> PosesFile:
    """:func:`tool_pose` of every configuration of ``q_file`` (Arrow IPC or CSV, columns
    ``q1_deg`` ... as ``ik --targets`` writes: :func:`pipeline.control.targets.read_joints`),
    under ``payload_kg`` as :func:`tool_pose`.

    ``out``: an Arrow file of the input's columns plus the poses (``x_cm`` ... ``rz_deg``,
    an ``ik --targets`` input in the design base frame) and ``outside_limits``, written
    atomically (metadata ``frame``); an existing file is replaced only with ``force``.
    ``frame``: as :func:`tool_pose`.
    """
    import pyarrow as pa

    from pipeline.atomic import check_new_file
    from pipeline.control.targets import TARGET_COLUMNS, read_joints
    from pipeline.robots.fk import chain_poses
    from pipeline.stages.tables import write_table

    model = _pose_model(robot, payload_kg)
    desc = model if isinstance(model, RobotDescription) else model.robot
    table, q = read_joints(q_file, desc)
    if out is not None:
        if frame != DEFAULT_FRAME:  # ik --targets would read them in the design base frame
            raise ArmsigError(
                f"--out writes an `ik --targets` input, in the {DEFAULT_FRAME} frame, not {frame}",
                fix=f"--json for {frame}-frame poses, or drop --frame",
            )
        if Path(out).resolve() == Path(q_file).resolve():
            raise ArmsigError(f"--out {out} is the --q-file file", fix="--out poses.arrow")
        check_new_file(out, "--out", force)
    if isinstance(model, RobotDescription):
        _session_options(payload_kg, frame)
        poses = chain_poses(desc, desc.design_chain(), q)
    else:
        poses = model.poses(q, design=design, frame=frame)
    if out is not None:
        values = np.concatenate([poses.xyz_cm, poses.rpy_deg], axis=1)
        extra = {c: pa.array(values[:, k], pa.float64()) for k, c in enumerate(TARGET_COLUMNS)}
        extra["outside_limits"] = pa.array([",".join(n) for n in poses.outside_limits])
        table = table.drop_columns([c for c in table.column_names if c in extra])
        for name, values_ in extra.items():
            table = table.append_column(name, values_)
        meta = {"robot": desc.name, "design": str(design), "frame": frame}
        if payload_kg is not None:
            meta["payload_kg"] = repr(float(payload_kg))
        write_table(Path(out), table, meta)
    joints = tuple(j.name for j in desc.joints)
    return PosesFile(desc.name, joints, q, poses, None if out is None else str(out), frame)


@dataclass(frozen=True)
class ToolController:
    """The controller of a session's signature, the label of its tool, and its verdict
    (``verdict``: status, None without one; ``warning``: a CHECK or an accepted FAIL, and a
    payload outside those the session measured)."""

    controller: Controller
    label: str
    verdict: str | None
    warning: str | None


def tool_controller(
    session: str | Path,
    tool: Sequence[float] | None = None,
    accept_verdict: bool = False,
    payload_kg: float | None = None,
) -> ToolController:
    """The controller of a session's signature, passed through its verdict
    (:func:`pipeline.signature.verdict.verdict_gate`: a FAIL is refused unless
    ``accept_verdict``).

    ``tool``: None for the signature's tool, else a user tool x y z (cm) rx ry rz (deg,
    fixed axes) in the design flange frame (:meth:`Controller.with_tool`);
    ``payload_kg``: the payload on the flange (:meth:`Controller.with_payload`; None: the
    one the session measured).
    """
    from pipeline.control.controller import Controller
    from pipeline.kinematics.transforms import transform_from_xyz_rpy
    from pipeline.signature.file import FILE_NAME
    from pipeline.signature.session import load_session_signature
    from pipeline.signature.verdict import verdict_gate

    sig = load_session_signature(Path(session) / FILE_NAME)
    warning = verdict_gate(sig.verdict, str(session), accept_verdict)
    status = None if sig.verdict is None else sig.verdict.status
    ctl = Controller.from_signature(sig)
    if payload_kg is not None:
        ctl = ctl.with_payload(payload_kg)
        warning = "; ".join(w for w in (warning, ctl.payload_warning) if w) or None
    if tool is None:
        return ToolController(ctl, "signature", status, warning)
    t = np.asarray(tool, float)
    ctl = ctl.with_tool(transform_from_xyz_rpy(t[:3], np.deg2rad(t[3:])))
    return ToolController(ctl, "flange " + " ".join(f"{v:g}" for v in tool), status, warning)


@dataclass(frozen=True)
class PoseSolution:
    """The joint readings ``q`` (deg / cm) of one pose, and how the solver got there."""

    joints: tuple[str, ...]
    units: tuple[str, ...]
    q: tuple[float, ...]
    status: str
    converged: bool
    iterations: int
    position_error_cm: float
    orientation_error_deg: float
    outside_limits: tuple[str, ...]  # joints outside their limits (status out_of_limits)
    branch_changed: bool  # no solution on the requested branch: this one is on another
    tool: str
    verdict: str | None = None  # the signature's verdict (None: it has none)
    verdict_warning: str | None = None  # a CHECK, or a FAIL accepted (accept_verdict)

    def to_dict(self) -> dict[str, Any]:
        """The fields as JSON types (``ik --json``)."""
        d = dataclasses.asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def solve_pose(
    session: str | Path,
    pose: Sequence[float],
    *,
    branch: str | None = None,
    method: str = "nr",
    tool: Sequence[float] | None = None,
    near: Sequence[float] | None = None,
    accept_verdict: bool = False,
    payload_kg: float | None = None,
) -> PoseSolution:
    """The joint readings that put the session's tool at ``pose``: x y z (cm) rx ry rz
    (deg, fixed axes) in the design base frame.

    ``branch``: Puma branch (default: that of ``near``, else of q^s); ``method``: ``nr``
    or ``jacobi``; ``tool``: a user tool (:func:`tool_controller`); ``near``: joint
    readings (deg / cm) to start from (:func:`pipeline.control.controller.solve_poses`);
    ``accept_verdict``: use a signature whose verdict is FAIL (else refused);
    ``payload_kg``: the payload on the flange (:func:`tool_controller`).
    """
    from pipeline.control.controller import solve_poses
    from pipeline.control.limits import outside_names
    from pipeline.kinematics.ik import STATUS_NAMES

    tc = tool_controller(session, tool, accept_verdict, payload_kg)
    ctl = tc.controller
    p = np.asarray(pose, float)
    q_near = None if near is None else np.asarray(near, float)
    q, res = solve_poses(ctl, p[:3], p[3:], [branch], method, q_near)
    joints = ctl.robot.joints
    return PoseSolution(
        joints=tuple(j.name for j in joints),
        units=tuple(j.unit for j in joints),
        q=tuple(float(v) for v in q[0]),
        status=STATUS_NAMES[int(res.status[0])],
        converged=bool(res.converged[0]),
        iterations=int(res.iterations[0]),
        position_error_cm=float(res.position_error_cm[0]),
        orientation_error_deg=float(np.degrees(res.orientation_error_rad[0])),
        outside_limits=outside_names(ctl.robot, res.q[:1])[0],
        branch_changed=bool(res.branch_changed is not None and res.branch_changed[0]),
        tool=tc.label,
        verdict=tc.verdict,
        verdict_warning=tc.warning,
    )


class RunRecord:
    """A frozen dataclass of what a targets command wrote, with ``summary`` its one line
    for people: :meth:`to_dict` gives the rest (``--json``)."""

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)  # type: ignore[call-overload]
        del d["summary"]
        return d  # type: ignore[no-any-return]


@dataclass(frozen=True)
class TargetsSolution(RunRecord):
    """What :func:`solve_targets` wrote (``ik --targets --json``: :meth:`to_dict`)."""

    targets: int
    converged: int
    failed: int
    out: str
    method: str
    tool: str
    summary: str
    verdict: str | None = None  # the signature's verdict (None: it has none)
    verdict_warning: str | None = None  # a CHECK, or a FAIL accepted (accept_verdict)


def solve_targets(
    session: str | Path,
    targets: str | Path,
    out: str | Path,
    *,
    method: str = "nr",
    tool: Sequence[float] | None = None,
    near: Sequence[float] | None = None,
    force: bool = False,
    accept_verdict: bool = False,
    payload_kg: float | None = None,
) -> TargetsSolution:
    """Solve the poses of the Arrow file ``targets`` (columns
    :data:`~pipeline.control.targets.TARGET_COLUMNS`, optional ``branch``) and write
    them with their joints to ``out`` (:func:`pipeline.control.targets.solve_arrow`);
    ``accept_verdict``, ``payload_kg`` as :func:`solve_pose`."""
    from pipeline.control.targets import solve_arrow
    from pipeline.stages.tables import read_table

    tc = tool_controller(session, tool, accept_verdict, payload_kg)
    q_near = None if near is None else np.asarray(near, float)
    summary, failed = solve_arrow(tc.controller, targets, out, method, tc.label, q_near, force)
    n = read_table(Path(out)).num_rows
    return TargetsSolution(
        n, n - failed, failed, str(out), method, tc.label, summary, tc.verdict, tc.warning
    )
