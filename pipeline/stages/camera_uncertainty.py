"""Stage ``uncertainty`` of a camera session: the predicted tool error of the camera's
signature over the workspace (issue 39; the pose sets' :mod:`pipeline.stages.uncertainty`).

The parameters' part: ``camera_fit``'s covariance of the chain (axis lines, the tool's
point and rotation; the lens marginalised: its rows and columns dropped) carried to the
tool at ``configurations`` random configurations within the limits (seeded as the audit
draws them, :mod:`pipeline.refine.uncertainty`), raw and after the base and tool
re-alignment. A camera's frames are physical (the tool's pose is measured in the fixed
body's frame, the hand-eye transforms are fitted): nothing re-aligns the signature
before it is used, so its prediction (``sigma_total_cm``, ``max95_cm``) is the raw part
(the camera audit's tool point, :mod:`pipeline.rig.camera_audit`); the aligned columns
say how much of it is placement (base and tool).

The unmodelled part (issue 41, :mod:`pipeline.refine.unmodelled`): the pixel residuals
carried to the target point as lateral lengths (``du · Z / fx``, ``dv · Z / fy``: what a
pixel is at that point's depth), judged by the fit's pixel χ² on its degrees of freedom.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import Stage
from pipeline.stages.session import session_robot
from pipeline.stages.uncertainty import Params, uncertainty_table

#: The groups of ``camera_fit`` rows that are the chain's parameters (the model's order).
KINEMATIC_GROUPS = ("axis", "point", "tool_rotation")


def kinematic_covariance(table: pa.Table) -> np.ndarray:
    """The chain's covariance (rad, cm) from a ``camera_fit`` table: its kinematic rows'
    block of the ``covariance`` column, the lens marginalised."""
    rows = table.to_pylist()
    kin = np.array([r["group"] in KINEMATIC_GROUPS for r in rows])
    f = np.where([r["unit"] == "deg" for r in rows], np.radians(1.0), 1.0)
    C = np.array([r["covariance"] for r in rows], float) * np.outer(f, f)
    return np.asarray(C[np.ix_(kin, kin)])


def camera_unmodelled(inputs: Mapping[str, Any]) -> Any:
    """:class:`~pipeline.refine.unmodelled.Unmodelled` of the fit's pixel residuals at
    the target points (module docstring)."""
    from pipeline.refine.unmodelled import unmodelled_error
    from pipeline.stages.camera_fit import camera_summary
    from pipeline.stages.camera_residuals import fitted_points

    det, P, uv, k = fitted_points(inputs)
    d = (uv - det.uv) * (P[:, 2:3] / k[:2])  # px → cm at the point's depth Z
    r = np.column_stack([d, np.zeros(len(d))])
    s = camera_summary(inputs["camera_fit"])
    free = int(s["n_residuals"]) - int(s["dof"])
    return unmodelled_error(r, free, float(s["chi2"]), int(s["dof"]), True, components=2)


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.camera_fit import observing
    from pipeline.refine.uncertainty import model_error_maps, predict, tool_poses
    from pipeline.stages.camera_fit import fitted_model

    robot = session_robot(inputs["session"])
    table = inputs["camera_fit"]
    model, x, _, q_sig = fitted_model(table, robot)
    at = observing(model, robot.random_configurations(params.configurations, params.seed), q_sig)
    Sigma = kinematic_covariance(table)
    A, B = model_error_maps(at, x)
    pred = predict(A, B, Sigma, params.seed)
    raw95 = predict(A, A, Sigma, params.seed).max95_cm  # the raw error's bound
    return uncertainty_table(tool_poses(at, x)[0], pred, raw95, camera_unmodelled(inputs), True)


STAGE = Stage(
    "uncertainty",
    1,
    ("session", "joints", "detections", "camera_fit"),
    Params(),
    compute,
    "predicted tool error of the camera's signature over random configurations (camera)",
)
