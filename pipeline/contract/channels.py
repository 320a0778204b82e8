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
#: sensor kind of ``/rig/description`` (absent: ``sonic``) -> channels of its recording
SENSOR_CHANNELS = {"sonic": CHANNELS, "points": POINT_CHANNELS}
#: topic -> schema file of the evaluation recording ``evaluation.mcap`` (docs/evaluation.md)
EVAL_CHANNELS = {
    "/eval/description": "eval_description",
    "/eval/teach": "eval_teach",
    "/eval/program": "eval_program",
    "/eval/measurement": "eval_measurement",
}
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
