"""Stage ``session``: the recording's description messages, verbatim."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import RECORDING, NoParams, Stage


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    rec = inputs[RECORDING]
    robot = rec.robot.get("robot", {})  # none: flange poses without joints (issue 40)
    return pa.table(
        {
            "robot_name": [str(robot.get("name", "?"))],
            "n_joints": [len(robot.get("joints", []))],
            "mode": [str(rec.robot.get("mode"))],
            "recording_sha256": [rec.sha256],
            "rig_json": [json.dumps(rec.rig, sort_keys=True)],
            "robot_json": [json.dumps(rec.robot, sort_keys=True)],
        }
    )


STAGE = Stage(
    "session", 2, (RECORDING,), NoParams(), compute, "description messages of the recording"
)


def session_robot_id(session: pa.Table) -> str | None:
    """The arm's own id (serial) recorded in the session; None when none was."""
    robot_id = json.loads(session.column("robot_json")[0].as_py()).get("robot_id")
    return None if robot_id is None else str(robot_id)


def session_robot(session: pa.Table):  # -> RobotDescription
    """The design robot description recorded in the session."""
    from pipeline.robots.description import description_from_dict

    doc = json.loads(session.column("robot_json")[0].as_py())
    if "robot" not in doc:  # flange poses without joints (issue 40)
        raise StageError(
            "the session has no arm (no /robot/description): its flange poses calibrate the "
            "camera only", fix="its calibration is camera_calibration.json, camera_info.yaml "
            "and report/report.md (`pipeline identify`)",
        )  # fmt: skip
    return description_from_dict(doc["robot"], source="/robot/description")


def session_sensor(session: pa.Table) -> str:
    """The recorded sensor kind: ``sonic`` (also when absent) or ``points``."""
    return str(json.loads(session.column("rig_json")[0].as_py()).get("sensor", "sonic"))


def session_kind(session: pa.Table) -> str:
    """The stage list's key (:data:`pipeline.stages.catalog.SENSOR_STAGE_MODULES`): the
    recorded sensor, or ``camera-flange`` for a camera session without an arm (flange
    poses, no joints: :attr:`pipeline.stages.recording.Recording.kind`)."""
    from pipeline.stages.recording import FLANGE_KIND

    sensor = session_sensor(session)
    no_arm = sensor == "camera" and session.column("n_joints")[0].as_py() == 0
    return FLANGE_KIND if no_arm else sensor


def session_plan(session: pa.Table) -> dict[str, Any]:
    """The recorded measurement plan and signature configuration."""
    doc = json.loads(session.column("robot_json")[0].as_py())
    return {"signature_q": doc["signature_q"], **doc["plan"]}


def session_geometry(session: pa.Table):  # -> DigitizerGeometry | None
    """The recorded digitizer geometry of a sonic session; None for a point sensor."""
    if session_sensor(session) != "sonic":
        return None
    from pipeline.sensor.geometry import DigitizerGeometry

    return DigitizerGeometry.from_dict(json.loads(session.column("rig_json")[0].as_py()))
