"""Stage ``camera_holdout`` of a camera session: the fit's error on held-out images
(issue 39; the math: :mod:`pipeline.refine.camera_holdout`), one row per held-out image
(``schemas/arrow/camera_holdout.json``). The refits use ``camera_fit``'s own parameters.
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
from pipeline.stages.camera_fit import detections_for_fit, reading_sigma, table_images


@dataclass(frozen=True)
class Params:
    """``fraction``: of the images held out, the last ones in measurement order (0.2:
    8 of 40 images, 30 of 150)."""

    fraction: float = 0.2

    def __post_init__(self) -> None:
        ok = bool(np.isfinite(self.fraction) and 0.0 < self.fraction < 0.5)
        check_param(self, "camera_holdout", "fraction", ok, "between 0 and 0.5")


def fit_params(table: pa.Table) -> Any:
    """The :class:`~pipeline.stages.camera_fit.Params` a ``camera_fit`` table was computed
    with (its provenance), so that a refit is the same fit."""
    from pipeline.stages.camera_fit import Params as FitParams

    recorded = (table.schema.metadata or {}).get(b"armsig.params")
    return FitParams(**json.loads(recorded)) if recorded else FitParams()


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.camera_holdout import camera_holdout

    det, design, lens, setup = detections_for_fit(inputs)
    fit = fit_params(inputs["camera_fit"])
    h = camera_holdout(det, design, lens, setup, params.fraction, intrinsics=fit.intrinsics,
                       prior_sigma=fit.prior_sigma(), loss=fit.loss,
                       f_scale=fit.f_scale,
                       reading_sigma=reading_sigma(inputs["session"]))  # fmt: skip
    columns = {
        "image": table_images(inputs["detections"])[h.image], "points": h.points,
        "rms_px": h.rms_px, "expected_px": h.expected_px, "design_rms_px": h.design_rms_px,
    }  # fmt: skip
    return arrow_table("camera_holdout", {k: np.asarray(v) for k, v in columns.items()})


STAGE = Stage(
    "camera_holdout",
    3,  # 2: the joint readings' rounding in the refit's covariance and the prediction;
    # 3: the images' shared error (refine/camera_readings.py) in both
    ("session", "joints", "detections", "camera_fit"),
    Params(),
    compute,
    "the camera fit's reprojection error on held-out images, and the design's (camera)",
)
