"""Stage ``positions`` of a point-sensor session: the ``/points`` messages as recorded.

The one stage that replaces ranges -> compensate -> triangulate when the recording's
sensor is ``points``; it writes the sensor-neutral ``positions`` table
(:mod:`pipeline.stages.positions`), one row per (sweep, step, target), with the
recorded uncertainty (``sigma_cm`` or the covariance) and orientation.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import RECORDING, NoParams, Stage
from pipeline.stages.joints import source_columns
from pipeline.stages.positions import positions_table


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    rec = inputs[RECORDING]
    if rec.sensor != "points":
        raise StageError(
            f"{rec.path}: the recording's sensor is {rec.sensor!r}",
            expected="a point-sensor recording (/rig/description sensor 'points')",
            fix="run `pipeline identify`; it picks the stages of the recorded sensor",
        )
    m = len(rec.point_sweep)
    one, zero = np.ones(m, np.int64), np.zeros(m, np.int64)
    return positions_table(
        rec.point_sweep,
        rec.point_step,
        rec.point_target,
        rec.points_cm,
        {"n_samples": one, "n_dropped": zero, "n_rejected": zero, "n_used": one},
        [None] * m,
        rec.point_sigma_cm,
        rec.point_cov_cm2,
        rec.point_wxyz,
        rec.point_orientation_sigma_deg,
        _sources(rec),
    )


def _sources(rec: Any) -> dict[str, Any]:
    """Each point's ``source_file`` and ``source_line``: its configuration's, joined by
    (sweep, step) from the joint states."""
    at = {
        (int(s), int(k)): i
        for i, (s, k) in enumerate(zip(rec.joint_sweep, rec.joint_step, strict=True))
    }
    keys = zip(rec.point_sweep, rec.point_step, strict=True)
    idx = np.array([at[(int(s), int(k))] for s, k in keys], np.int64).reshape(-1)
    return source_columns(rec.joint_source_file[idx], rec.joint_source_line[idx])


STAGE = Stage(
    "positions",
    3,  # 2: the recorded orientation's σ (orientation_sigma_deg); 3: source_file and
    # source_line of an imported row (issue 42)
    (RECORDING,),
    NoParams(),
    compute,
    "target positions as recorded on /points (point sensor)",
)
