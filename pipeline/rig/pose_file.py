"""A pose plan file: the joint readings a robot program runs, one pose per row (issue 28).

CSV (comma-separated, ``#`` comment lines first), a robot program or a person can read:

    # armsig pose plan: ur10, 30 poses; predicted RMS 0.0011 cm, 95 % 0.0016 cm
    step,shoulder_pan_deg,shoulder_lift_deg,elbow_deg,wrist_1_deg,wrist_2_deg,wrist_3_deg
    0,-12.5,...

One column per joint, ``<joint name>_deg`` (revolute) or ``_cm`` (prismatic): the
controller's readings (through the robot's coupling when it has one), in the order of the
robot description. ``pipeline plan`` writes it, ``pipeline simulate --plan`` records
exactly these poses. Parsed by polars; a file that does not match the robot is refused
with one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.atomic import write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.robots.description import RobotDescription


def plan_columns(robot: RobotDescription) -> list[str]:
    """``step`` and one column per joint, named with its unit."""
    return ["step"] + [f"{j.name}_{j.unit}" for j in robot.joints]


def write_pose_plan(path: Path, robot: RobotDescription, q: np.ndarray, comment: str) -> Path:
    """Write joint values ``q`` (K, n, boundary units) as the robot's readings."""
    readings = robot.readings_from_joints(np.asarray(q, float))
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append(",".join(plan_columns(robot)))
    lines += [f"{k}," + ",".join(f"{v:.6f}" for v in row) for k, row in enumerate(readings)]
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


def write_sweep_plan(
    path: Path, robot: RobotDescription, sweeps: list[tuple[str, np.ndarray]], comment: str
) -> Path:
    """Write a sweep plan: a ``sweep`` column (the joint swept, or ``tool``: the sweep names
    of the recording, :mod:`pipeline.sweeps`) before :func:`plan_columns`, one row per
    position, each sweep's joint values ``q`` (N_i, n, boundary units) as the robot's
    readings, in the order given (the measuring order)."""
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append(",".join(["sweep", *plan_columns(robot)]))
    for name, q in sweeps:
        readings = robot.readings_from_joints(np.asarray(q, float))
        lines += [f"{name},{k}," + ",".join(f"{v:.6f}" for v in row)
                  for k, row in enumerate(readings)]  # fmt: skip
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


def read_pose_plan(path: Path, robot: RobotDescription) -> np.ndarray:
    """Joint values (K, n, boundary units) of a pose plan file for ``robot``, in step order;
    refused with one line when its columns, steps or values do not fit the robot."""
    import polars as pl

    fix = "write it with `pipeline plan` (docs/plan.md), or match the columns named above"
    try:
        df = pl.read_csv(path, comment_prefix="#", infer_schema_length=0)
    except (OSError, pl.exceptions.PolarsError) as exc:
        raise ArmsigError(f"{path}: not a readable pose plan", got=str(exc)[:200], fix=fix) from exc
    want = plan_columns(robot)
    if df.columns != want:
        raise ArmsigError(
            f"{path}: the columns do not match robot {robot.name}",
            expected=",".join(want),
            got=",".join(df.columns)[:200],
            fix=fix,
        )
    try:
        values = df.cast(pl.Float64).to_numpy()
    except pl.exceptions.PolarsError as exc:
        raise ArmsigError(f"{path}: a value is not a number", got=str(exc)[:200], fix=fix) from exc
    if len(values) == 0 or not np.isfinite(values).all():
        raise ArmsigError(
            f"{path}: no poses, or a value that is empty or not finite",
            expected="one row per pose, every value a finite number",
            fix=fix,
        )
    if not np.array_equal(values[:, 0], np.arange(len(values))):
        raise ArmsigError(
            f"{path}: steps are not 0, 1, 2, ...", got=str(values[:5, 0].tolist()), fix=fix
        )
    q = robot.joints_from_readings(values[:, 1:])
    lim = robot.limits
    out = (q < lim[:, 0]) | (q > lim[:, 1])
    if out.any():
        k, j = (int(v) for v in np.argwhere(out)[0])
        raise ArmsigError(
            f"{path}: step {k} puts joint {robot.joints[j].name} outside its limits",
            expected=f"{lim[j, 0]:g} to {lim[j, 1]:g} {robot.joints[j].unit}",
            got=f"{q[k, j]:g}",
            fix=fix,
        )
    return np.asarray(q, float)
