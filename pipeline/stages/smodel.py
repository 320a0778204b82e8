"""Stage ``smodel``: B_i = S̄_{i-1}^-1 S̄_i (4.51) and the six parameters (4.52)-(4.57)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.frames import chain_from_frames, matrices_to_columns
from pipeline.stages.session import session_robot


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.kinematics.smodel import smodel_from_matrix

    robot = session_robot(inputs["session"])
    chain = chain_from_frames(inputs["chain"], robot.prismatic)
    B = chain.links  # Eq. (4.51)
    p = smodel_from_matrix(B)  # Eq. (4.52)-(4.57), ERRATA sign of b and atan2
    return pa.table(
        {
            "link": np.arange(1, robot.n_joints + 1, dtype=np.int32),
            "type": [j.type for j in robot.joints],
            "beta_deg": np.degrees(p.beta),
            "d_bar_cm": p.d_bar,
            "a_bar_cm": p.a_bar,
            "alpha_bar_deg": np.degrees(p.alpha_bar),
            "gamma_deg": np.degrees(p.gamma),
            "b_cm": p.b,
            **matrices_to_columns(B),
        }
    )


STAGE = Stage(
    "smodel",
    2,  # 2: from the signature chain (stage chain), refined by default
    ("chain", "session"),
    NoParams(),
    compute,
    "S-Model link transforms and parameters",
)
