"""Stage ``dh``: encoder offsets (4.59)/(4.60) and the pseudo D-H model (4.71)-(4.73).

For prismatic joints these are the modified D-H parameters of (3.12)-(3.15);
relocating S_{i-1} to make a_i = 0 (4.61)-(4.70) is not done here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.kinematics.signature import pseudo_dh_from_chain
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.frames import chain_from_frames
from pipeline.stages.session import session_robot


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    robot = session_robot(inputs["session"])
    pris = robot.prismatic
    p = pseudo_dh_from_chain(chain_from_frames(inputs["frames"], pris))
    off = np.where(pris, p.q_offset, np.degrees(p.q_offset))
    design_d = np.array([np.nan if j.prismatic else j.dh.d_cm for j in robot.joints])

    def masked(v: np.ndarray) -> pa.Array:
        return pa.array(v, mask=np.isnan(v))

    return pa.table(
        {
            "joint": np.arange(1, robot.n_joints + 1, dtype=np.int32),
            "type": [j.type for j in robot.joints],
            "q_offset_deg": masked(np.where(pris, np.nan, off)),
            "q_offset_cm": masked(np.where(pris, off, np.nan)),
            "theta_deg": masked(np.degrees(p.theta)),
            "d_cm": masked(p.d),
            "a_cm": p.a,
            "alpha_deg": np.degrees(p.alpha),
            "design_d_cm": masked(design_d),
            "design_a_cm": np.array([j.dh.a_cm for j in robot.joints]),
            "design_alpha_deg": np.array([j.dh.alpha_deg for j in robot.joints]),
        }
    )


STAGE = Stage(
    "dh", 2, ("frames", "session"), NoParams(), compute, "encoder offsets and pseudo D-H parameters"
)
