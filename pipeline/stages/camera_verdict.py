"""Stage ``verdict`` of a camera session: PASS / CHECK / FAIL of its signature, with the
reasons (issue 39; the rules: :mod:`pipeline.refine.camera_verdict`, docs/verdict.md).

One row of the verdict schema, as every session's: the predicted tool error from stage
``uncertainty`` (cm), the χ² of the whitened pixels from ``camera_fit``, the design
misfit from ``chain``; the held-out numbers in cm are null (a camera measures no tool
position) and the held-out images' pixels (``camera_holdout``) decide the held-out rules;
``gain`` and ``worse_sigmas`` are theirs. Every threshold is a parameter, as for every
session: ``--param verdict.holdout_ratio=3``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.refine.verdict import Evidence, predicted_limit_cm
from pipeline.stages.base import Stage
from pipeline.stages.verdict import NUMBERS, Params, verdict_table


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.camera_verdict import PixelHoldout, judge_camera
    from pipeline.signature.alignment import design_alignment
    from pipeline.stages.camera_fit import camera_summary
    from pipeline.stages.frames import chain_from_frames
    from pipeline.stages.session import session_robot
    from pipeline.stages.uncertainty import summary

    robot = session_robot(inputs["session"])
    s = camera_summary(inputs["camera_fit"])
    unc = summary(inputs["uncertainty"])
    assert unc is not None  # a camera fit always has its covariance
    misfit = design_alignment(chain_from_frames(inputs["chain"], robot.prismatic), robot)[2]
    fixed = s["intrinsics"] == "fixed"  # the lens held as given is no finding
    held = tuple(h["name"] for h in s["identifiability"].get("held", [])
                 if not (fixed and h["name"].startswith("camera.")))  # fmt: skip
    dof = int(s["dof"])
    parameters = unc["sigma_position_rms_cm"]
    e = Evidence(
        refined=True, status=str(s["status"]),
        chi2_per_dof=float(s["chi2"]) / dof if dof > 0 else None,
        predicted_rms_cm=unc["sigma_total_rms_cm"], predicted_p95_cm=unc["sigma_total_p95_cm"],
        predicted_parameters_rms_cm=parameters, unmodelled_rms_cm=unc["sigma_unmodelled_rms_cm"],
        misfit_sigmas=misfit / parameters if parameters else None, held=held,
        design_misfit_cm=misfit, reach_cm=robot.reach_cm,
    )  # fmt: skip
    hold = inputs["camera_holdout"]
    h = PixelHoldout(*(hold.column(c).to_numpy() for c in ("rms_px", "expected_px",
                                                          "design_rms_px")))  # fmt: skip
    sigma_px = float(np.median(inputs["detections"].column("sigma_px").to_numpy()))
    v = judge_camera(e, h, sigma_px, params)
    numbers = {k: None for k in NUMBERS} | {
        "predicted_rms_cm": e.predicted_rms_cm, "predicted_p95_cm": e.predicted_p95_cm,
        "predicted_max95_cm": unc["max95_cm"], "predicted_parameters_rms_cm": parameters,
        "unmodelled_rms_cm": e.unmodelled_rms_cm, "gain": h.gain, "worse_sigmas": h.worse_sigmas,
        "design_misfit_rms_cm": misfit, "misfit_sigmas": e.misfit_sigmas,
        "chi2_per_dof": e.chi2_per_dof, "design_reach_cm": robot.reach_cm,
        "predicted_limit_cm": predicted_limit_cm(e, params),
    }  # fmt: skip
    return verdict_table(v, numbers)


STAGE = Stage(
    "verdict",
    1,
    ("session", "detections", "camera_fit", "uncertainty", "camera_holdout", "chain"),
    Params(),
    compute,
    "PASS / CHECK / FAIL of the camera's signature, with the reasons (camera)",
)
