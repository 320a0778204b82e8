"""Stage ``hand_eye_holdout`` of a session of flange poses without joints (issue 40): every
image held out once, the camera's calibration refitted without it (the math:
:mod:`pipeline.refine.hand_eye_holdout`), one row per image
(``schemas/arrow/hand_eye_holdout.json``). The refits use ``camera_fit``'s own
parameters. The schema metadata ``armsig.hand_eye_holdout`` holds the folds, the RMS
over every held-out point of each column and the in-sample RMS beside them, or why no
image was held out (a session of :data:`~pipeline.refine.camera_fit.MIN_IMAGES` images).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.schemas import arrow_table
from pipeline.stages.base import Stage, check_param
from pipeline.stages.camera_fit import camera_summary
from pipeline.stages.camera_holdout import fit_params
from pipeline.stages.hand_eye_fit import hand_eye_inputs

META = b"armsig.hand_eye_holdout"


@dataclass(frozen=True)
class Params:
    """``folds``: contiguous blocks of the images in measurement order (5: each refit
    keeps 80 % of them; more when a fold would leave the refit too few)."""

    folds: int = 5

    def __post_init__(self) -> None:
        check_param(self, "hand_eye_holdout", "folds", 2 <= self.folds <= 100, "2 to 100")


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.camera_fit import MIN_IMAGES
    from pipeline.refine.hand_eye_holdout import hand_eye_folds, hand_eye_holdout

    det, flange, lens, setup, images = hand_eye_inputs(inputs)
    in_sample = float(camera_summary(inputs["camera_fit"])["rms_px"])
    fold = hand_eye_folds(det.n_images, params.folds)
    if fold is None:
        why = (f"{det.n_images} images: holding one out leaves fewer than the {MIN_IMAGES} "
               "a fit needs")  # fmt: skip
        summary: dict[str, Any] = {"folds": 0, "in_sample_rms_px": in_sample, "reason": why}
        names = ("fold", "image", "points", "rms_px", "expected_px", "start_rms_px")
        empty: dict[str, list[float]] = {n: [] for n in names}
        return arrow_table("hand_eye_holdout", empty, {META: json.dumps(summary).encode()})
    fit = fit_params(inputs["camera_fit"])
    h = hand_eye_holdout(det, flange, lens, setup, fold, intrinsics=fit.intrinsics,
                         prior_sigma=fit.prior_sigma(), loss=fit.loss,
                         f_scale=fit.f_scale)  # fmt: skip
    summary = {
        "folds": int(fold.max()) + 1, "in_sample_rms_px": in_sample,
        "rms_px": h.overall(h.rms_px), "expected_px": h.overall(h.expected_px),
        "start_rms_px": h.overall(h.start_rms_px), "reason": None,
    }  # fmt: skip
    columns = {
        "fold": h.fold, "image": images, "points": h.points, "rms_px": h.rms_px,
        "expected_px": h.expected_px, "start_rms_px": h.start_rms_px,
    }  # fmt: skip
    return arrow_table("hand_eye_holdout", {k: np.asarray(v) for k, v in columns.items()},
                       {META: json.dumps(summary).encode()})  # fmt: skip


def holdout_summary(table: pa.Table) -> dict[str, Any]:
    """The stage's summary (schema metadata ``armsig.hand_eye_holdout``)."""
    return dict(json.loads((table.schema.metadata or {})[META]))


STAGE = Stage(
    "hand_eye_holdout",
    2,  # 2: the images' shared error (refine/camera_readings.py) in the prediction
    ("session", "flange_poses", "detections", "camera_fit"),
    Params(),
    compute,
    "every image held out once and the camera's calibration refitted without it "
    "(camera, no joints)",
)
