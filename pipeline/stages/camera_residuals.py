"""Stage ``camera_residuals`` of a camera session: the reprojection residual of every
detected point under the fitted chain and lens (``schemas/arrow/camera_residuals.json``;
the report's figure of residual vectors on the image plane)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.schemas import arrow_table
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.camera_fit import detections_for_fit, fitted_model, table_images
from pipeline.stages.session import session_robot
from pipeline.sweeps import POSES_SWEEP


def fitted_points(inputs: Mapping[str, Any]) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """The fit's detections, every detected point in the camera (D, 3) cm under the fitted
    chain, its predicted pixel (D, 2) and the fitted intrinsics (9,)."""
    from pipeline.refine.camera_block import camera_points
    from pipeline.refine.camera_fit import observing
    from pipeline.sensor.camera import project

    det, _, _, setup = detections_for_fit(inputs)
    robot = session_robot(inputs["session"])
    model, x, intrinsics, q_sig = fitted_model(inputs["camera_fit"], robot)
    at = observing(model, det.q, q_sig)
    t, R = at.positions(x)[det.image], at.tool_rotations(x)[det.image]
    P = camera_points(setup, t, R, det.local)[0]
    return det, P, project(P, intrinsics), intrinsics


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    det, _, uv, _ = fitted_points(inputs)
    return residual_table(inputs["detections"], table_images(inputs["detections"]), det, uv)


def residual_table(detections: pa.Table, images: np.ndarray, det: Any, uv: np.ndarray) -> pa.Table:
    """The residual rows of the fit's detections ``det`` (of the ``poses`` images, in the
    ``detections`` table's order; ``images`` their steps) predicted at ``uv`` (D, 2)."""
    use = detections.column("sweep").to_numpy() == POSES_SWEEP  # the fit's images
    columns = {
        "image": images[det.image],
        "point_id": detections.column("point_id").to_numpy()[use],
        "u_px": det.uv[:, 0], "v_px": det.uv[:, 1],
        "du_px": uv[:, 0] - det.uv[:, 0], "dv_px": uv[:, 1] - det.uv[:, 1],
    }  # fmt: skip
    return arrow_table("camera_residuals", {k: np.asarray(v) for k, v in columns.items()})


STAGE = Stage(
    "camera_residuals",
    1,
    ("session", "joints", "detections", "camera_fit"),
    NoParams(),
    compute,
    "reprojection residual of every detected point under the fitted chain and lens (camera)",
)
