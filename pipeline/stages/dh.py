"""Stage ``dh``: encoder offsets (4.59)/(4.60) and the pseudo D-H model (4.71)-(4.73).

The main columns are the *true* D-H parameters: every prismatic joint's S-Model
frame is relocated so that its line of translation meets the next joint axis,
``a_i = 0`` (4.61)-(4.70), with the encoder offset (4.73)
(:mod:`pipeline.kinematics.true_dh`). The ``modified_*`` columns keep the
modified D-H parameters of (3.12)-(3.15) taken from the S-Model frames as
identified (``a_i ≠ 0`` on prismatic joints). Both models reproduce the
signature exactly; without prismatic joints they are equal.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.frames import chain_from_frames
from pipeline.stages.session import session_robot

if TYPE_CHECKING:
    from pipeline.kinematics.signature import PseudoDH


def _masked(v: np.ndarray) -> pa.Array:
    return pa.array(v, mask=np.isnan(v))


def _columns(p: PseudoDH, pris: np.ndarray, prefix: str = "") -> dict[str, pa.Array]:
    """The six D-H columns of one pseudo D-H model, boundary units."""
    off = np.where(pris, p.q_offset, np.degrees(p.q_offset))
    return {
        f"{prefix}q_offset_deg": _masked(np.where(pris, np.nan, off)),
        f"{prefix}q_offset_cm": _masked(np.where(pris, off, np.nan)),
        f"{prefix}theta_deg": _masked(np.degrees(p.theta)),
        f"{prefix}d_cm": _masked(p.d),
        f"{prefix}a_cm": pa.array(p.a),
        f"{prefix}alpha_deg": pa.array(np.degrees(p.alpha)),
    }


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.kinematics.signature import pseudo_dh_from_chain
    from pipeline.kinematics.true_dh import true_dh_from_chain

    robot = session_robot(inputs["session"])
    pris = robot.prismatic
    chain = chain_from_frames(inputs["chain"], pris)
    design_d = np.array([np.nan if j.prismatic else j.dh.d_cm for j in robot.joints])
    return pa.table(
        {
            "joint": np.arange(1, robot.n_joints + 1, dtype=np.int32),
            "type": [j.type for j in robot.joints],
            **_columns(true_dh_from_chain(chain), pris),
            **_columns(pseudo_dh_from_chain(chain), pris, "modified_"),
            "design_d_cm": _masked(design_d),
            "design_a_cm": np.array([j.dh.a_cm for j in robot.joints]),
            "design_alpha_deg": np.array([j.dh.alpha_deg for j in robot.joints]),
        }
    )


STAGE = Stage(
    "dh",
    4,  # 4: from the signature chain (stage chain)
    ("chain", "session"),
    NoParams(),
    compute,
    "encoder offsets and true (and modified) pseudo D-H parameters",
)
