"""Stage ``residuals``: every target position's residual from its joint's features (Fig. 6-11).

With several targets in a sweep, the residuals are those of its best-conditioned target
(``targets_used[0]`` of the features table), whose plane and circle the features give.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.features import sweep_points
from pipeline.stages.session import session_robot


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    robot = session_robot(inputs["session"])
    n, pris = robot.n_joints, robot.prismatic
    out: dict[str, list[Any]] = {
        k: [] for k in ("joint", "step", "q_deg", "q_cm", "normal_cm", "radial_cm")
    }
    for row in inputs["features"].to_pylist():
        i = row["joint"]
        best = row["targets_used"][0]
        p, q, steps = sweep_points(inputs["positions"], inputs["joints"], i, n, pris, best)
        axis = np.array([row["axis_x"], row["axis_y"], row["axis_z"]])
        c = np.array([row["center_x_cm"], row["center_y_cm"], row["center_z_cm"]])
        d = p - c
        along = d @ axis
        inplane = np.linalg.norm(d - along[:, None] * axis, axis=1)
        prismatic = row["type"] == "prismatic"
        out["joint"] += [i] * len(p)
        out["step"] += [int(s) for s in steps]
        out["q_deg"] += [None] * len(p) if prismatic else list(q)
        out["q_cm"] += list(q) if prismatic else [None] * len(p)
        # Prismatic: distance from the line; revolute: signed plane distance and radial error.
        out["normal_cm"] += list(inplane if prismatic else along)
        out["radial_cm"] += [None] * len(p) if prismatic else list(inplane - row["radius_cm"])
    return pa.table(
        {
            "joint": pa.array(out["joint"], pa.int32()),
            "step": pa.array(out["step"], pa.int32()),
            "q_deg": pa.array(out["q_deg"], pa.float64()),
            "q_cm": pa.array(out["q_cm"], pa.float64()),
            "normal_cm": pa.array(out["normal_cm"], pa.float64()),
            "radial_cm": pa.array(out["radial_cm"], pa.float64()),
        }
    )


STAGE = Stage(
    "residuals",
    3,
    ("positions", "joints", "features", "session"),
    NoParams(),
    compute,
    "per-point normal and radial residuals",
)
