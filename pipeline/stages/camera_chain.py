"""Stage ``chain`` of a camera session: the fitted chain every later stage and
``signature.json`` read (issue 39).

The frames ``S̄_0 … S̄_n`` and the tool of ``camera_fit``'s fitted rows (frames schema,
as the pose sets' stage ``chain``): the sensor frame is the fixed body's (the camera's
optical frame eye-to-hand, the target's eye-in-hand) and the tool is the body on the
flange (the target, or the camera's optical frame) with its fitted rotation
(:meth:`pipeline.refine.kinematics.ChainModel.signature_frames`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.camera_frames import frames_of
from pipeline.stages.session import session_robot


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    return frames_of(inputs, "value")


STAGE = Stage(
    "chain",
    1,
    ("session", "camera_fit"),
    NoParams(),
    compute,
    "the signature chain: the camera fit's frames and tool (camera)",
)


def camera_refinement(table: pa.Table) -> dict[str, Any]:
    """The signature file's ``refinement`` section of a camera session's ``camera_fit``
    table: the fit's status and χ² (whitened pixels, ``level`` pixels) and the lens's
    fitted parameters with their σ (``sensor_calibration``, as a digitizer's)."""
    from pipeline.stages.camera_fit import camera_summary

    s = camera_summary(table)
    dof = int(s["dof"])
    lens = [r for r in table.to_pylist() if r["group"] == "intrinsics"]
    return {
        "enabled": True, "level": "pixels", "status": s["status"],
        "iterations": int(s["iterations"]), "chi2": float(s["chi2"]), "dof": dof,
        "noise_scale": float(np.sqrt(s["chi2"] / dof)) if dof > 0 else 0.0,
        "sensor_calibration": [{"name": r["name"], "unit": r["unit"], "value": r["value"],
                                "sigma": r["sigma"]} for r in lens],
        "verdict": None,
    }  # fmt: skip


def camera_section(session: pa.Table, table: pa.Table, X: np.ndarray, Y: np.ndarray) -> dict:
    """The signature file's ``camera`` section: the set-up, the lens with σ (OpenCV's
    names and order, its image size) and both hand-eye transforms (cm) in the design's
    base and flange frames as the design alignment ``X``, ``Y`` places them (the fixed
    body is the sensor frame, so it sits at ``X⁻¹`` in the base; the moving body is the
    signature's tool, at ``tool_design · Y`` on the flange)."""
    from pipeline.kinematics.transforms import invert_transform
    from pipeline.signature.file import matrix_rows
    from pipeline.stages.camera_fit import camera_summary

    rig = json.loads(session.column("rig_json")[0].as_py())
    s = camera_summary(table)
    robot = session_robot(session)
    fixed, moving = ("camera", "target") if s["setup"] == "eye-to-hand" else ("target", "camera")
    lens = [r for r in table.to_pylist() if r["group"] == "intrinsics"]
    return {
        "setup": s["setup"], "intrinsics_mode": s["intrinsics"],
        "width_px": int(rig["camera"]["width_px"]), "height_px": int(rig["camera"]["height_px"]),
        "distortion_model": "plumb_bob",
        "intrinsics": [{"name": r["name"].removeprefix("camera."), "unit": r["unit"],
                        "value": r["value"], "sigma": r["sigma"]} for r in lens],
        f"{fixed}_in_base": matrix_rows(invert_transform(X)),
        f"{moving}_in_flange": matrix_rows(robot.tool.matrix() @ Y),
        "images": int(s["n_images"]), "points": int(s["n_points"]),
        "rms_px": float(s["rms_px"]),
    }  # fmt: skip
