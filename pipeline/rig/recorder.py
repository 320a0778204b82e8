"""Write a session recording: MCAP, zstd chunks, JSON messages with embedded JSON Schemas.

Channel names and schemas are the contract between a rig (real or simulated)
and the pipeline; see ``schemas/mcap/``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from pipeline.atomic import atomic_write
from pipeline.schemas import mcap_json_schema

#: topic -> schema file in schemas/mcap/
CHANNELS = {
    "/rig/description": "rig_description",
    "/robot/description": "robot_description",
    "/robot/joint_state": "joint_state",
    "/sonic/ranges": "sonic_ranges",
}
#: topic -> schema file of the evaluation recording ``evaluation.mcap`` (docs/evaluation.md)
EVAL_CHANNELS = {
    "/eval/description": "eval_description",
    "/eval/teach": "eval_teach",
    "/eval/program": "eval_program",
    "/eval/measurement": "eval_measurement",
}
PROFILE = "armsig"
LIBRARY = "armsig-rig"  # fixed so that the same seed gives the same bytes


@dataclass(frozen=True)
class Message:
    """One message: topic, time in ns, JSON-ready payload."""

    topic: str
    time_ns: int
    payload: dict[str, Any]


def write_recording(
    path: str | Path, messages: list[Message], channels: dict[str, str] = CHANNELS
) -> None:
    """Write ``messages`` (in time order) to ``path`` atomically; ``channels``: topic -> schema."""
    with atomic_write(path, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.ZSTD, chunk_size=1 << 20)  # type: ignore[arg-type]
        writer.start(profile=PROFILE, library=LIBRARY)
        channel_ids: dict[str, int] = {}
        for topic, schema_name in channels.items():
            schema = mcap_json_schema(schema_name)
            sid = writer.register_schema(
                name=schema["title"],
                encoding="jsonschema",
                data=json.dumps(schema, sort_keys=True).encode(),
            )
            channel_ids[topic] = writer.register_channel(
                topic=topic, message_encoding="json", schema_id=sid
            )
        sequence: dict[str, int] = dict.fromkeys(channels, 0)
        for msg in messages:
            writer.add_message(
                channel_id=channel_ids[msg.topic],
                log_time=msg.time_ns,
                publish_time=msg.time_ns,
                sequence=sequence[msg.topic],
                data=json.dumps(msg.payload, separators=(",", ":"), allow_nan=False).encode(),
            )
            sequence[msg.topic] += 1
        writer.finish()
