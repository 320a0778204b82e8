"""Stage ``camera_residuals`` of a session of flange poses without joints (issue 40): the
reprojection residual of every detected point under the fitted hand-eye transforms and
lens (``schemas/arrow/camera_residuals.json``, as a joint session's)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.camera_fit import camera_summary
from pipeline.stages.camera_residuals import residual_table
from pipeline.stages.hand_eye_fit import hand_eye_inputs


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.refine.hand_eye import predicted_pixels
    from pipeline.sensor.camera import Intrinsics

    det, flange, lens, setup, images = hand_eye_inputs(inputs)
    fit = inputs["camera_fit"]
    s = camera_summary(fit)
    k = [r["value"] for r in fit.to_pylist() if r["group"] == "intrinsics"]
    fitted = Intrinsics(lens.width_px, lens.height_px, *k)
    uv = predicted_pixels(det, flange, setup, np.array(s["fixed_in_base_cm"]),
                          np.array(s["tool_in_flange_cm"]), fitted)  # fmt: skip
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
