"""The channels of the two recordings and their compiled JSON Schemas (``schemas/mcap/``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

#: topic -> schema file in schemas/mcap/ of a sonic session recording ``recording.mcap``
CHANNELS = {
    "/rig/description": "rig_description",
    "/robot/description": "robot_description",
    "/robot/joint_state": "joint_state",
    "/sonic/ranges": "sonic_ranges",
}
#: topic -> schema file of a point-sensor session recording (``/rig/description`` sensor
#: ``points``): the measurement channel ``/points`` replaces ``/sonic/ranges``.
POINT_CHANNELS = {
    **{t: s for t, s in CHANNELS.items() if t != "/sonic/ranges"},
    "/points": "points",
}
#: topic -> schema file of a camera session recording (``/rig/description`` sensor
#: ``camera``, issue 39): the detections of the target in each image.
CAMERA_CHANNELS = {
    **{t: s for t, s in CHANNELS.items() if t != "/sonic/ranges"},
    "/camera/detections": "camera_detections",
}
#: topic -> schema file of an imported image set without joint readings (issue 40): the
#: images by content hash, their detections, the flange poses the robot reported.
IMAGE_SET_CHANNELS = {
    "/rig/description": "rig_description",
    "/camera/images": "camera_images",
    "/camera/detections": "camera_detections",
    "/robot/flange_pose": "flange_pose",
}
#: An imported image set with joint readings (issue 40): a camera recording, and its
#: images by content hash (a channel the reader allows and does not need).
CAMERA_IMAGE_CHANNELS = {**CAMERA_CHANNELS, "/camera/images": "camera_images"}
#: A point session whose configurations are written in blocks of columns (issue 45,
#: ``pipeline import``): ``/points/block`` beside, or instead of, the per-configuration
#: ``/robot/joint_state`` and ``/points`` messages (:mod:`pipeline.contract.blocks`).
POINT_BLOCK_CHANNELS = {**POINT_CHANNELS, "/points/block": "points_block"}
#: Channels a recording of a sensor kind may hold besides its own.
OPTIONAL_CHANNELS = {"camera": ("/camera/images",), "points": ("/points/block",)}
#: sensor kind of ``/rig/description`` (absent: ``sonic``) -> channels of its recording
SENSOR_CHANNELS = {"sonic": CHANNELS, "points": POINT_CHANNELS, "camera": CAMERA_CHANNELS}
#: topic -> schema file of the evaluation recording ``evaluation.mcap`` (docs/evaluation.md)
EVAL_CHANNELS = {
    "/eval/description": "eval_description",
    "/eval/teach": "eval_teach",
    "/eval/program": "eval_program",
    "/eval/measurement": "eval_measurement",
}
#: A robot id (its serial) in ``/robot/description`` ``robot_id``: what a fleet tells arms
#: of one model apart by (schemas/mcap/robot_description.json holds the same pattern).
ROBOT_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:/-]{0,63}$"


def check_robot_id(robot_id: str) -> str:
    """``robot_id`` if it is one (:data:`ROBOT_ID_PATTERN`), else a one-line refusal."""
    import re

    from pipeline.errors import ArmsigError

    if not re.fullmatch(ROBOT_ID_PATTERN, robot_id):
        raise ArmsigError(
            "bad --robot-id",
            expected="1 to 64 letters, digits and . _ : / - (a serial number), "
            "starting with a letter or digit",
            got=repr(robot_id),
        )
    return robot_id


#: Words of older recordings, read as today's: (topic, field) -> {old: new}.
#: MCAP metadata record naming the foreign file(s) an imported recording was converted
#: from (``pipeline import``); its ``file`` is every row's ``source_file`` when the joint
#: states carry none (a recording of one file).
SOURCE_METADATA = "armsig.source"
LEGACY_VALUES = {("/robot/description", "mode"): {"real": "hardware"}}


def validator(schema_name: str) -> Callable[[Any], Any]:
    """The compiled validator of ``schemas/mcap/<schema_name>.json`` (raises
    ``fastjsonschema.JsonSchemaValueException`` naming the field)."""
    from pipeline.schemas import compiled_validator

    return compiled_validator(f"mcap/{schema_name}.json")


def upgrade_legacy(topic: str, payload: dict[str, Any]) -> None:
    """Replace the old words of :data:`LEGACY_VALUES` in ``payload`` in place."""
    for (t, field), words in LEGACY_VALUES.items():
        if t == topic and isinstance(payload.get(field), str) and payload[field] in words:
            payload[field] = words[payload[field]]
