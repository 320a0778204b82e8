"""Stage ``ranges``: every raw slant range of the recording, long format."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import RECORDING, NoParams, Stage


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.sensor.geometry import MICROPHONES

    rec = inputs[RECORDING]
    m = len(rec.cycle_sweep)
    rep = 20  # 5 sparkers x 4 microphones per cycle
    r = rec.ranges_cm.reshape(m, rep)
    return pa.table(
        {
            "sweep": np.repeat(rec.cycle_sweep, rep).astype(np.int32),
            "step": np.repeat(rec.cycle_step, rep).astype(np.int32),
            "repeat": np.repeat(rec.cycle_repeat, rep).astype(np.int32),
            "sparker": np.tile(np.repeat(np.arange(1, 6), 4), m).astype(np.int32),
            "microphone": np.tile(np.array(MICROPHONES * 5), m),
            "range_cm": pa.array(r.ravel(), mask=np.isnan(r.ravel())),
            "t_s": np.repeat(rec.cycle_t_s, rep),
        }
    )


STAGE = Stage(
    "ranges",
    3,  # 3: t_s from the measurement times (MCAP publish_time), not the log times (issue 33)
    (RECORDING,),
    NoParams(),
    compute,
    "raw slant ranges, one row per echo",
)
