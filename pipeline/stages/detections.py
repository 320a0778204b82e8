"""Stage ``detections`` of a camera session: the ``/camera/detections`` messages as
recorded, one row per detected target point (issue 39; ``schemas/arrow/detections.json``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pyarrow as pa

from pipeline.errors import StageError
from pipeline.schemas import arrow_table
from pipeline.stages.base import RECORDING, NoParams, Stage


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    rec = inputs[RECORDING]
    if rec.sensor != "camera":
        raise StageError(
            f"{rec.path}: the recording's sensor is {rec.sensor!r}",
            expected="a camera recording (/rig/description sensor 'camera')",
            fix="run `pipeline identify`; it picks the stages of the recorded sensor",
        )
    columns = {
        "sweep": rec.detection_sweep,
        "image": rec.detection_step,
        "point_id": rec.detection_point,
        "u_px": rec.detection_uv_px[:, 0],
        "v_px": rec.detection_uv_px[:, 1],
        "sigma_px": rec.detection_sigma_px,
    }
    return arrow_table("detections", columns)


STAGE = Stage(
    "detections",
    1,
    (RECORDING,),
    NoParams(),
    compute,
    "target points detected in each image, as recorded on /camera/detections (camera)",
)
