"""Stage ``camera_residuals`` of a session of flange poses without joints (issue 40): the
reprojection residual of every detected point under the fitted hand-eye transforms and
lens (``schemas/arrow/camera_residuals.json``, as a joint session's)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.camera_residuals import residual_table
from pipeline.stages.hand_eye_fit import fitted_hand_eye, hand_eye_inputs


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.refine.hand_eye import predicted_pixels

    det, flange, lens, setup, images = hand_eye_inputs(inputs)
    fixed, tool, fitted = fitted_hand_eye(inputs["camera_fit"], lens)
    uv = predicted_pixels(det, flange, setup, fixed, tool, fitted)
    return residual_table(inputs["detections"], images, det, uv)


STAGE = Stage(
    "camera_residuals",
    1,
    ("session", "flange_poses", "detections", "camera_fit"),
    NoParams(),
    compute,
    "reprojection residual of every detected point under the fitted hand-eye transforms "
    "and lens (camera, no joints)",
)
