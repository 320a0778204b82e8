"""Stage ``camera_fit`` of a session of flange poses without joints (issue 40): both
hand-eye transforms and the lens fitted to the detections, the flange poses taken as the
robot reported them (the math: :mod:`pipeline.refine.hand_eye`; the arm is not
calibrated).

The stage has the name, the parameters (``--param camera_fit.intrinsics=fixed|prior``,
:class:`~pipeline.stages.camera_fit.Params`) and the table schema
(``schemas/arrow/camera_fit.json``) of a joint session's camera fit; its rows are the
body on the flange (``point``, ``tool_rotation``: in the flange frame), the fixed body in
the base (``fixed``) and the intrinsics (``intrinsics``), radians as degrees. The schema
metadata ``armsig.camera_fit`` holds the fit's summary, every image's reprojection error,
and both hand-eye transforms as 4 × 4 matrices (cm).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import Stage
from pipeline.stages.camera_fit import Params, fit_pixels, fit_table

#: What the summary says of the arm when the recording does not (``/rig/description`` arm).
ARM = "not calibrated: flange poses, no joint readings"


def hand_eye_inputs(inputs: Mapping[str, Any]) -> tuple[Any, np.ndarray, Any, str, np.ndarray]:
    """(Detections, flange poses (m, 4, 4, cm), stated lens, set-up, image steps) of the
    stage tables."""
    from pipeline.refine.hand_eye import flange_detections
    from pipeline.sensor.camera import Intrinsics
    from pipeline.stages.flange_poses import flange_matrices

    rig = json.loads(inputs["session"].column("rig_json")[0].as_py())
    images, image, local, uv, sigma = fit_pixels(rig, inputs["detections"])
    det = flange_detections(image, local, uv, sigma, len(images))
    flange = flange_matrices(inputs["flange_poses"], images)
    return det, flange, Intrinsics.from_dict(rig["camera"]), str(rig["setup"]), images


def _arm(inputs: Mapping[str, Any]) -> str:
    return str(json.loads(inputs["session"].column("rig_json")[0].as_py()).get("arm", ARM))


def fitted_hand_eye(table: pa.Table, lens: Any) -> tuple[np.ndarray, np.ndarray, Any]:
    """(The fixed body in the base, the flange's body in the flange (4, 4, cm), the fitted
    lens :class:`~pipeline.sensor.camera.Intrinsics` of the size of ``lens``) of this
    stage's table."""
    from pipeline.sensor.camera import Intrinsics
    from pipeline.stages.camera_fit import camera_summary

    s = camera_summary(table)
    k = [r["value"] for r in table.to_pylist() if r["group"] == "intrinsics"]
    fitted = Intrinsics(lens.width_px, lens.height_px, *k)
    return np.array(s["fixed_in_base_cm"]), np.array(s["tool_in_flange_cm"]), fitted


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.hand_eye import fit_hand_eye, fixed_in_base, tool_in_flange

    det, flange, lens, setup, images = hand_eye_inputs(inputs)
    fit = fit_hand_eye(det, flange, lens, setup, params.intrinsics, params.prior_sigma(),
                       params.loss, params.f_scale)  # fmt: skip
    groups = ["point"] * 3 + ["tool_rotation"] * 3 + ["fixed"] * 6 + ["intrinsics"] * 9
    extra = {
        "arm": _arm(inputs),
        "start_hand_eye": {"fixed_in_base": fit.start.fixed_in_base.tolist(),
                           "tool_in_flange": fit.start.tool_in_flange.tolist(),
                           "method": fit.start.method},
        "fixed_in_base_cm": fixed_in_base(fit).tolist(),
        "tool_in_flange_cm": tool_in_flange(fit).tolist(),
    }  # fmt: skip
    return fit_table(fit, det, params, setup, groups, images, extra)


STAGE = Stage(
    "camera_fit",
    3,  # 2: the covariance rows of the joint session's table (schema camera_fit v2);
    # 3: the identifiability analysed at the lens start's σ (refine/camera_fit.py, tolerances)
    # and the images' shared error in the covariance (refine/camera_readings.py)
    ("session", "flange_poses", "detections"),
    Params(),
    compute,
    "both hand-eye transforms and the lens fitted to the pixels, the flange poses as "
    "given (camera, no joints: the arm is not calibrated)",
)
