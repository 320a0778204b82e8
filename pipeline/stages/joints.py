"""Stage ``joints``: commanded and encoder joint positions of every configuration."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import RECORDING, NoParams, Stage


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    rec = inputs[RECORDING]
    k, n = rec.q_encoder.shape
    pris = np.array([j["type"] == "prismatic" for j in rec.robot["robot"]["joints"]])
    is_p = np.tile(pris, k)
    cmd = rec.q_commanded.ravel()
    enc = rec.q_encoder.ravel()
    return pa.table(
        {
            "sweep": np.repeat(rec.joint_sweep, n).astype(np.int32),
            "step": np.repeat(rec.joint_step, n).astype(np.int32),
            "joint": np.tile(np.arange(1, n + 1), k).astype(np.int32),
            "q_cmd_deg": pa.array(cmd, mask=is_p),
            "q_deg": pa.array(enc, mask=is_p),
            "q_cmd_cm": pa.array(cmd, mask=~is_p),
            "q_cm": pa.array(enc, mask=~is_p),
            "t_s": np.repeat(rec.joint_t_s, n),
        }
    )


STAGE = Stage("joints", 2, (RECORDING,), NoParams(), compute, "joint positions per configuration")
