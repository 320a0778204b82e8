"""robot_cal_tools' kinematic-measurement YAML: 6-D target poses keyed by time.

Each entry ``KEY: {pose: {x, y, z, qw, qx, qy, qz}, target_joints: [...], camera_joints: []}``
holds the target's pose in the camera frame (m, unit quaternion) and the joint
readings (rad) of the robot carrying it. The pose position is the measured target
(``target``), its orientation goes to ``orientation_wxyz``. Entries are taken in key order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.rows import ANGLE_DEG, LENGTH_CM, MeasuredRows
from pipeline.importers.sscanss2 import read_text
from pipeline.importers.yamlfile import load_yaml
from pipeline.robots.description import RobotDescription
from pipeline.stages.recording import CHECK_SWEEP

FORMAT = "rct"
TARGET = "target"
_POSE = ("x", "y", "z", "qw", "qx", "qy", "qz")
#: A stored quaternion's norm may differ from 1 by this much (rounding of a text file);
#: more means the entry is not a rotation.
QUAT_NORM_TOL = 1e-3


def _entry(src: str, key: str, e: Any, n: int) -> tuple[list[float], list[float]]:
    where = f"{src}: entry '{key}'"
    pose = e.get("pose") if isinstance(e, dict) else None
    joints = e.get("target_joints") if isinstance(e, dict) else None
    if not isinstance(pose, dict) or any(k not in pose for k in _POSE):
        raise ImportFileError(
            f"{where}: missing pose field(s)",
            expected="pose: {" + ", ".join(_POSE) + "}",
            got=repr(pose)[:120],
            fix="complete or delete the entry",
        )
    if not isinstance(joints, list) or len(joints) != n:
        raise ImportFileError(
            f"{where}: target_joints does not fit the robot",
            expected=f"{n} joint readings (rad)",
            got=repr(joints)[:120],
            fix="use the robot description of this positioner (--robot)",
        )
    try:
        return [float(pose[k]) for k in _POSE], [float(v) for v in joints]
    except (TypeError, ValueError):
        raise ImportFileError(
            f"{where}: a pose value or joint reading is not a number",
            fix="correct or delete the entry",
        ) from None


def read_rct(path: Path, robot: RobotDescription) -> MeasuredRows:
    """Parse the YAML into rows (deg / cm; every row a check until sweeps are selected)."""
    src = path.name
    for j in robot.joints:
        if j.prismatic:
            raise ImportFileError(
                f"{src}: robot {robot.name} has prismatic joint {j.name!r}",
                expected="revolute joints (robot_cal_tools' target_joints are in rad)",
                fix="use a robot description with revolute joints",
            )
    data = load_yaml(read_text(path), src)
    if not isinstance(data, dict) or not data:
        raise ImportFileError(
            f"{src}: no entries", expected="a mapping of time keys to {pose, target_joints}"
        )
    keys = sorted(data, key=str)
    parsed = [_entry(src, str(k), data[k], robot.n_joints) for k in keys]
    pose = np.array([p for p, _ in parsed])
    quat = pose[:, 3:]
    norm = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(~(np.abs(norm - 1.0) <= QUAT_NORM_TOL))
    if len(bad):
        raise ImportFileError(
            f"{src}: entry '{keys[bad[0]]}': the quaternion is not a rotation",
            expected=f"norm 1 ± {QUAT_NORM_TOL:g}",
            got=f"{norm[bad[0]]:g}",
            fix="correct or delete the entry",
        )
    q = np.array([j for _, j in parsed]) * ANGLE_DEG["rad"]
    return MeasuredRows(
        source=path,
        where=tuple(f"entry '{k}'" for k in keys),
        sweep=np.full(len(keys), CHECK_SWEEP),
        q=q,
        targets={TARGET: pose[:, :3] * LENGTH_CM["m"]},
        orientation_wxyz=quat / norm[:, None],
    )
