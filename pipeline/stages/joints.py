"""Stage ``joints``: commanded and encoder joint positions of every configuration.

Readings become joint values here, through the robot's coupling when it has one
(joint = C · reading + offset, schemas/robot_description.md); every later stage
sees joint values only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import RECORDING, NoParams, Stage


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.robots.description import description_from_dict

    rec = inputs[RECORDING]
    k, n = rec.q_encoder.shape
    robot = description_from_dict(rec.robot["robot"], source="/robot/description")
    is_p = np.tile(robot.prismatic, k)
    cmd = robot.joints_from_readings(rec.q_commanded).ravel()
    enc = robot.joints_from_readings(rec.q_encoder).ravel()
    payload = rec.joint_payload_kg
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
            "payload_kg": pa.array(np.repeat(payload, n), mask=np.repeat(np.isnan(payload), n)),
        }
    )


STAGE = Stage(
    "joints",
    4,  # 3: t_s from the measurement times (MCAP publish_time), not the log times (issue 33);
    # 4: payload_kg (issue 27)
    (RECORDING,),
    NoParams(),
    compute,
    "joint positions per configuration",
)
