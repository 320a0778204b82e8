"""Compensated targets for a controller that keeps its nominal model (``pipeline compensate``).

Most industrial controllers accept no new kinematics: they solve every target with the
design (nominal) model. The usual remedy is to rewrite the program's targets. For each
desired tool pose, :func:`compensate_targets`

1. solves the joint readings ``q`` that put the real arm's tool there, on its signature
   (:class:`~pipeline.control.controller.Controller`: joint limits and branches honoured,
   the ``ik --targets`` solve of :func:`pipeline.control.targets.solved_columns`);
2. writes the pose the nominal controller must be commanded to go to those readings:
   the design model's forward kinematics at ``q``, ``design(q) · Y``, of the same tool.

Both poses are in the *design base frame* (the robot's mounting surface as the design model
defines it), the frame ``ik --targets`` reads and a nominal controller works in; the
signature is mapped there by the design alignment ``X = sensor_from_design_base`` of the
signature file (Section 5.3). The tool is the signature's tool, ``Y =
design_flange_to_tool`` from the design flange, unless a user tool is given (as ``ik
--tool``): the nominal controller's tool data must be that same tool.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.control.poses import RunRecord, tool_controller
from pipeline.control.targets import (
    TARGET_COLUMNS,
    check_output,
    holds_joints,
    joint_columns,
    reached_summary,
    read_joints,
    read_targets,
    solved_columns,
    write_columns,
)

#: Columns of the desired poses in a ``compensate`` output (the input's pose columns).
DESIRED_COLUMNS = tuple(f"desired_{c}" for c in TARGET_COLUMNS)


@dataclass(frozen=True)
class CompensatedTargets(RunRecord):
    """What :func:`compensate_targets` wrote; ``summary``: its one line for people.

    ``max_correction_cm`` / ``max_correction_deg``: the largest change from a desired pose
    to its compensated pose over the targets reached (0 if none)."""

    targets: int
    converged: int
    failed: int
    out: str
    tool: str
    max_correction_cm: float
    max_correction_deg: float
    summary: str
    verdict: str | None = None  # the signature's verdict (None: it has none)
    verdict_warning: str | None = None  # a CHECK, or a FAIL accepted (accept_verdict)


def compensate_targets(
    session: str | Path,
    targets: str | Path,
    out: str | Path,
    *,
    tool: Sequence[float] | None = None,
    method: str = "nr",
    force: bool = False,
    accept_verdict: bool = False,
) -> CompensatedTargets:
    """Write to ``out`` (Arrow IPC, atomically) the pose to command to the nominal controller
    for each desired pose of ``targets`` (an ``ik --targets`` file: columns
    :data:`~pipeline.control.targets.TARGET_COLUMNS`, optional ``branch``, design base frame,
    cm / deg).

    Output columns: the input's, its poses moved to :data:`DESIRED_COLUMNS`; the
    compensated poses in :data:`~pipeline.control.targets.TARGET_COLUMNS` (null where the
    target is not reached: see ``status``); ``correction_cm`` / ``correction_deg`` (from
    desired to compensated); and the columns of ``ik --targets`` (joint readings,
    ``status``, ``outside_limits``, ...). ``tool``: a user tool as :func:`tool_controller`
    (the nominal controller's tool data); ``method``: ``nr`` or ``jacobi``; ``force``:
    replace an existing ``out``; ``accept_verdict``: use a FAIL signature (else refused).
    """
    import pyarrow as pa

    from pipeline.kinematics.transforms import pose_error, transform_from_xyz_rpy, wrap_angle

    tc = tool_controller(session, tool, accept_verdict)
    ctl = tc.controller
    if holds_joints(targets, ctl.robot):
        return _compensate_joints(tc, targets, out, method, force)
    table, desired, branches = read_targets(targets)
    check_output(out, targets, force, "compensated.arrow")
    q, res, solved = solved_columns(ctl, desired, branches, method)
    nominal = ctl.poses(q, design=True)  # design(q) · Y in the design base frame
    # Each angle within 180° of the desired one (the same rotation): columns that compare.
    turn = np.degrees(wrap_angle(np.radians(nominal.rpy_deg - desired[:, 3:])))
    compensated = np.concatenate([nominal.xyz_cm, desired[:, 3:] + turn], axis=1)
    T_desired = transform_from_xyz_rpy(desired[:, :3], np.deg2rad(desired[:, 3:]))
    dp, dth = pose_error(T_desired, nominal.matrix)
    dth = np.degrees(dth)
    missed = ~res.converged  # a pose for joints that miss the target is no answer
    extra: dict[str, Any] = {}
    for k, name in enumerate(DESIRED_COLUMNS):
        extra[name] = pa.array(desired[:, k], pa.float64())
    for k, name in enumerate(TARGET_COLUMNS):
        extra[name] = pa.array(compensated[:, k], pa.float64(), mask=missed)
    extra["correction_cm"] = pa.array(dp, pa.float64(), mask=missed)
    extra["correction_deg"] = pa.array(dth, pa.float64(), mask=missed)
    extra.update(solved)
    meta = {"signature": ctl.robot.name, "tool": tc.label, "method": method}
    meta["poses"] = "compensated: command to the nominal (design) controller, design base frame"
    note = write_columns(table.drop_columns(list(TARGET_COLUMNS)), extra, out, meta)
    summary, failed = reached_summary(res, out)
    reached = ~missed
    return CompensatedTargets(
        targets=len(q),
        converged=len(q) - failed,
        failed=failed,
        out=str(out),
        tool=tc.label,
        max_correction_cm=float(dp[reached].max()) if reached.any() else 0.0,
        max_correction_deg=float(dth[reached].max()) if reached.any() else 0.0,
        summary=summary + note,
        verdict=tc.verdict,
        verdict_warning=tc.warning,
    )


def _taught(names: tuple[str, ...]) -> list[str]:
    """Columns of the taught joint readings in a ``compensate`` output of a joints file."""
    return [f"taught_{c}" for c in names]


def _compensate_joints(
    tc: Any, targets: str | Path, out: str | Path, method: str, force: bool
) -> CompensatedTargets:
    """:func:`compensate_targets` of a file of joint readings taught on the nominal model
    (columns :func:`joint_columns`): each is the pose ``design(q) · Y``, for which the
    signature's readings are solved from the taught ones; the output's joint columns hold
    them, ``taught_q...`` the input's, the pose columns the taught pose, and
    ``correction_cm`` / ``correction_deg`` how far the real arm is from it at the taught
    readings (what the compensation removes)."""
    import pyarrow as pa

    from pipeline.kinematics.transforms import pose_error

    ctl = tc.controller
    table, taught = read_joints(targets, ctl.robot, "--targets")
    check_output(out, targets, force, "compensated.csv")
    pose = ctl.poses(taught, design=True)
    desired = np.concatenate([pose.xyz_cm, pose.rpy_deg], axis=1)
    q, res, solved = solved_columns(ctl, desired, None, method, near=taught)
    dp, dth = pose_error(pose.matrix, ctl.poses(taught).matrix)
    dth = np.degrees(dth)
    missed = ~res.converged
    names = joint_columns(ctl.robot)
    extra: dict[str, Any] = {}
    for k, name in enumerate(_taught(names)):
        extra[name] = pa.array(taught[:, k], pa.float64())
    for k, name in enumerate(TARGET_COLUMNS):
        extra[name] = pa.array(desired[:, k], pa.float64())
    extra["correction_cm"] = pa.array(dp, pa.float64())
    extra["correction_deg"] = pa.array(dth, pa.float64())
    extra.update(solved)
    for name in names:  # not reached: no compensated readings
        extra[name] = pa.array(extra[name].to_numpy(zero_copy_only=False), mask=missed)
    meta = {"signature": ctl.robot.name, "tool": tc.label, "method": method,
            "joints": "compensated: the readings to command, for the taught pose"}  # fmt: skip
    note = write_columns(table.drop_columns(list(names)), extra, out, meta)
    summary, failed = reached_summary(res, out)
    reached = ~missed
    return CompensatedTargets(
        targets=len(q), converged=len(q) - failed, failed=failed, out=str(out),
        tool=tc.label,
        max_correction_cm=float(dp[reached].max()) if reached.any() else 0.0,
        max_correction_deg=float(dth[reached].max()) if reached.any() else 0.0,
        summary=summary + note, verdict=tc.verdict, verdict_warning=tc.warning,
    )  # fmt: skip
