"""Stage ``residuals``: every target position's residual from its joint's features (Fig. 6-11)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.session import session_robot


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    robot = session_robot(inputs["session"])
    tri, joints, feat = inputs["triangulate"], inputs["joints"], inputs["features"]
    n = robot.n_joints
    out: dict[str, list[Any]] = {
        k: [] for k in ("joint", "step", "q_deg", "q_cm", "normal_cm", "radial_cm")
    }
    for row in feat.to_pylist():
        i = row["joint"]
        sel = tri.filter(pa.compute.equal(tri.column("sweep"), i))
        p = np.stack(
            [sel.column(c).to_numpy(zero_copy_only=False) for c in ("x_cm", "y_cm", "z_cm")], 1
        )
        p = p.astype(float)
        steps = sel.column("step").to_numpy()
        js = joints.filter(
            pa.compute.and_(
                pa.compute.equal(joints.column("sweep"), i),
                pa.compute.equal(joints.column("joint"), i),
            )
        )
        col = "q_cm" if row["type"] == "prismatic" else "q_deg"
        q_by_step = dict(
            zip(js.column("step").to_pylist(), js.column(col).to_pylist(), strict=True)
        )
        ok = ~np.isnan(p).any(axis=1)
        axis = np.array([row["axis_x"], row["axis_y"], row["axis_z"]])
        c = np.array([row["center_x_cm"], row["center_y_cm"], row["center_z_cm"]])
        d = p[ok] - c
        along = d @ axis
        inplane = d - along[:, None] * axis
        if row["type"] == "prismatic":
            normal = np.linalg.norm(inplane, axis=1)
            radial = [None] * len(normal)
        else:
            normal = along
            radial = list(np.linalg.norm(inplane, axis=1) - row["radius_cm"])
        for k, s in enumerate(steps[ok]):
            out["joint"].append(i)
            out["step"].append(int(s))
            q = q_by_step.get(int(s))
            out["q_deg"].append(None if row["type"] == "prismatic" else q)
            out["q_cm"].append(q if row["type"] == "prismatic" else None)
            out["normal_cm"].append(float(normal[k]))
            r = radial[k]
            out["radial_cm"].append(None if r is None else float(r))
    del n
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
    1,
    ("triangulate", "joints", "features", "session"),
    NoParams(),
    compute,
    "per-point normal and radial residuals",
)
