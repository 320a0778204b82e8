"""Stage ``camera_fit`` of a camera session: the arm, both hand-eye transforms and the lens
fitted to the detections (issue 39; the math: :mod:`pipeline.refine.camera_fit`).

This module adapts the tables to the math: the ``detections`` rows become
:class:`~pipeline.refine.camera_fit.Detections` (each point's target coordinates from the
recorded target, each image's joint values from ``joints`` by its step, ``q̄^s`` from the
recorded plan), the recorded lens is the start (or the held lens, or the prior's mean),
and the solution becomes one row per parameter (``schemas/arrow/camera_fit.json``;
radians as degrees).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.optim.lm import LOSSES
from pipeline.schemas import arrow_table
from pipeline.stages.base import Stage, check_param
from pipeline.stages.session import session_plan, session_robot
from pipeline.sweeps import POSES_SWEEP

INTRINSICS = ("fitted", "fixed", "prior")


@dataclass(frozen=True)
class Params:
    """``intrinsics``: fitted (from the recorded lens), fixed (held at it), or prior
    (fitted with the recorded lens as a prior of σ ``prior_focal_px`` on fx and fy,
    ``prior_center_px`` on cx and cy, ``prior_distortion`` on k1 … k3); ``loss`` and
    ``f_scale``: the robust loss, its scale in σ of the pixel noise (as ``refine``'s)."""

    intrinsics: str = "fitted"
    loss: str = "soft_l1"
    f_scale: float = 3.0
    prior_focal_px: float = 10.0
    prior_center_px: float = 10.0
    prior_distortion: float = 0.05

    def __post_init__(self) -> None:
        check_param(self, "camera_fit", "intrinsics", self.intrinsics in INTRINSICS,
                    " or ".join(INTRINSICS))  # fmt: skip
        check_param(self, "camera_fit", "loss", self.loss in LOSSES, " or ".join(LOSSES))
        for name in ("f_scale", "prior_focal_px", "prior_center_px", "prior_distortion"):
            value = getattr(self, name)
            check_param(self, "camera_fit", name, bool(np.isfinite(value) and value > 0),
                        "a number > 0")  # fmt: skip

    def prior_sigma(self) -> np.ndarray:
        """σ of the prior (9,), OpenCV's order."""
        return np.array([self.prior_focal_px] * 2 + [self.prior_center_px] * 2
                        + [self.prior_distortion] * 5)  # fmt: skip


def detections_for_fit(inputs: Mapping[str, Any]) -> tuple[Any, Any, Any, str]:
    """(Detections, design chain, stated lens, set-up) of the stage tables."""
    from pipeline.refine.camera_fit import Detections
    from pipeline.sensor.camera import Intrinsics
    from pipeline.stages.frames import readings_at
    from pipeline.units import joints_to_internal

    session = inputs["session"]
    rig = json.loads(session.column("rig_json")[0].as_py())
    robot = session_robot(session)
    pris = robot.prismatic
    images, image, local, uv, sigma = fit_pixels(rig, inputs["detections"])
    q = readings_at(inputs["joints"], POSES_SWEEP, images, robot.n_joints, pris)
    q_sig = robot.joints_from_readings(np.asarray(session_plan(session)["signature_q"], float))
    det = Detections(image, local, uv, sigma, joints_to_internal(q, pris),
                     joints_to_internal(q_sig, pris))  # fmt: skip
    return det, robot.design_chain(), Intrinsics.from_dict(rig["camera"]), str(rig["setup"])


def fit_pixels(rig: dict[str, Any], table: pa.Table) -> tuple[np.ndarray, ...]:
    """The fit's detections of a ``detections`` table (the ``poses`` images: validation
    images stay out): the images (steps, sorted), each point's image (0 … m − 1), its
    target coordinates (cm, from the recorded target), pixel and σ."""
    from pipeline.sensor.target import target_from_dict

    ids, local = target_from_dict(rig["target"], "/rig/description target").points()
    use = table.column("sweep").to_numpy() == POSES_SWEEP
    steps = table.column("image").to_numpy()[use].astype(np.int64)
    images, image = np.unique(steps, return_inverse=True)
    at = np.searchsorted(ids, table.column("point_id").to_numpy()[use])  # ids are sorted
    uv = np.stack([table.column("u_px").to_numpy()[use], table.column("v_px").to_numpy()[use]], 1)
    sigma = table.column("sigma_px").to_numpy()[use].astype(float)
    return images, image.astype(np.int64), local[at], uv, sigma


def reading_sigma(session: pa.Table) -> np.ndarray:
    """The joint readings' σ (n,) rad / cm: the encoders' rounding, resolution / √12."""
    from pipeline.refine.camera_readings import encoder_sigma

    robot = session_robot(session)
    return encoder_sigma(robot.encoder_resolution, robot.prismatic)


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.camera_fit import fit_camera

    det, design, lens, setup = detections_for_fit(inputs)
    fit = fit_camera(det, design, lens, setup, params.intrinsics, params.prior_sigma(),
                     params.loss, params.f_scale,
                     reading_sigma=reading_sigma(inputs["session"]))  # fmt: skip
    s = fit.solution
    groups = ["axis"] * fit.model.n_axis_params + ["point"] * 3 + ["tool_rotation"] * 3
    groups += ["intrinsics"] * len(fit.block.x0)
    extra = {
        "start_frames_cm": fit.model.frames0.tolist(),
        "q_signature": det.q_signature.tolist(),
        "frames_cm": fit.model.signature_frames(s.x[: fit.model.n_params], 0).tolist(),
        "start_hand_eye": {"fixed_in_base": fit.start.fixed_in_base.tolist(),
                           "tool_in_flange": fit.start.tool_in_flange.tolist()},
    }  # fmt: skip
    return fit_table(fit, det, params, setup, groups, table_images(inputs["detections"]), extra)


def fit_table(
    fit: Any, det: Any, params: Params, setup: str, groups: list[str], images: np.ndarray,
    extra: dict[str, Any],
) -> pa.Table:  # fmt: skip
    """The ``camera_fit`` table of a fit: one row per parameter in ``groups`` (radians as
    degrees), its summary (the fit, every image's reprojection, the identifiability, the
    held line, and ``extra``) in the schema metadata."""
    from pipeline.refine.camera_fit import held_line
    from pipeline.refine.identifiability import summary as identifiability_summary

    s = fit.solution
    units = [*fit.model.param_units, *fit.block.param_units]
    deg = np.array([u == "rad" for u in units])
    scale = np.where(deg, np.degrees(1.0), 1.0)
    summary = {
        "setup": setup, "intrinsics": params.intrinsics, "status": s.status,
        "message": s.message, "iterations": s.iterations, "n_images": det.n_images,
        "n_points": len(det.image), "n_residuals": s.n_residuals, "chi2": s.chi2,
        "dof": s.dof, "rms_px": fit.rms_px, "loss": params.loss, "f_scale": params.f_scale,
        "images": image_rows(fit, images),
        "identifiability": identifiability_summary(fit.identifiability, fit.names,
                                                   det.n_images, len(det.image)),
        "warning": held_line(fit, float(np.median(det.sigma_px))),
        # the images' shared error (refine/camera_readings.py, image_pose_variance): px per
        # coordinate of the independent pixels and of the share common to an image's points
        "shared_error": {"independent_px": float(np.sqrt(fit.independent_px2)),
                         "shared_px": float(np.sqrt(3.0 * fit.shared_px2)),
                         "counted": bool(fit.shared_px2 > 0)},
        **extra,
    }  # fmt: skip
    columns = {
        "group": groups, "name": list(fit.names),
        "unit": ["deg" if d else u for d, u in zip(deg, units, strict=True)],
        "start": fit.x_start * scale, "value": s.x * scale, "sigma": s.sigma * scale,
        "covariance": list(s.covariance * np.outer(scale, scale)),
    }  # fmt: skip
    return arrow_table("camera_fit", columns, {b"armsig.camera_fit": json.dumps(summary).encode()})


STAGE = Stage(
    "camera_fit",
    7,  # 2: per-image reprojection errors and the identifiability in the summary; 3: the
    # start frames, q̄^s (rad / cm) and the fitted frames S̄_0 … S̄_n and tool (cm);
    # 4: the covariance rows (the signature's uncertainty, holdout and verdict);
    # 5: the covariance with the joint readings' rounding (refine/camera_readings.py);
    # 6: lens terms held by the design's tolerance alone analysed again at their start's
    # σ (refine/camera_fit.py, tolerances); 7: the images' shared error in the covariance
    # (refine/camera_readings.py, image_pose_variance) and the summary's shared_error
    ("session", "joints", "detections"),
    Params(),
    compute,
    "the arm, both hand-eye transforms and the lens fitted to the pixels (camera)",
)


def table_images(table: pa.Table) -> np.ndarray:
    """The image numbers (steps) of the fit's images, in its order."""
    use = table.column("sweep").to_numpy() == POSES_SWEEP
    return np.unique(table.column("image").to_numpy()[use])


def image_rows(fit: Any, images: np.ndarray) -> list[list[float]]:
    """Per image: [image, points, rms px, largest px] of the fit's reprojection."""
    count, rms, worst = fit.image_residuals()
    return [[int(i), int(c), float(r), float(w)]
            for i, c, r, w in zip(images, count, rms, worst, strict=True)]  # fmt: skip


def camera_summary(table: pa.Table) -> dict[str, Any]:
    """The fit's summary (schema metadata ``armsig.camera_fit``)."""
    return dict(json.loads((table.schema.metadata or {})[b"armsig.camera_fit"]))


def fitted_model(table: pa.Table, robot: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """The fitted chain of a ``camera_fit`` table: the model, its parameters ``x_kin``
    (internal units), the intrinsics (9,) and ``q̄^s`` (rad / cm)."""
    from pipeline.refine.kinematics import ChainModel

    s = camera_summary(table)
    rows = table.to_pylist()
    value = np.array([r["value"] for r in rows])
    value = np.where([r["unit"] == "deg" for r in rows], np.radians(value), value)
    kin = np.array([r["group"] != "intrinsics" and r["group"] != "fixed" for r in rows])
    empty = np.zeros(0, np.int64)
    model = ChainModel(np.array(s["start_frames_cm"]), robot.prismatic, empty,
                       np.zeros((0, robot.n_joints)), empty, ("tool",), True)  # fmt: skip
    intrinsics = value[[r["group"] == "intrinsics" for r in rows]]
    return model, value[kin], intrinsics, np.array(s["q_signature"])


def camera_warning(table: pa.Table) -> str | None:
    """The fit's one-line warning (parameters held: what to measure), None without one."""
    meta = (table.schema.metadata or {}).get(b"armsig.camera_fit")
    return None if meta is None else json.loads(meta).get("warning")
