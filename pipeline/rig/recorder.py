"""Write a session recording: MCAP, zstd chunks, JSON messages with embedded JSON Schemas.

Channel names and schemas are the contract between a rig (real or simulated)
and the pipeline; see ``schemas/mcap/`` and :mod:`pipeline.contract`. Every file
carries chunk CRCs, a data-section CRC, message indexes and the ``armsig.content``
digest of its messages (schemas/README.md).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.atomic import atomic_write, check_writable
from pipeline.contract.channels import CHANNELS, EVAL_CHANNELS
from pipeline.contract.digest import DIGEST_NAME, content_digest
from pipeline.contract.mcap_write import checked_writer, json_bytes
from pipeline.errors import ArmsigError
from pipeline.schemas import mcap_json_schema

__all__ = ["CHANNELS", "EVAL_CHANNELS", "Message", "refuse_existing_recording", "write_recording"]

PROFILE = "armsig"
LIBRARY = "armsig-rig"  # fixed so that the same seed gives the same bytes


@dataclass(frozen=True)
class Message:
    """One message: topic, time in ns (when it was measured: the MCAP ``publish_time``),
    JSON-ready payload, and when a logger wrote it (``log_time``; None: ``time_ns``)."""

    topic: str
    time_ns: int
    payload: dict[str, Any]
    log_time_ns: int | None = None


def write_recording(
    path: str | Path,
    messages: list[Message],
    channels: dict[str, str] = CHANNELS,
    metadata: dict[str, dict[str, str]] | None = None,
) -> None:
    """Write ``messages`` (in log-time order) to ``path`` atomically; ``channels``: topic -> schema;
    ``metadata``: extra MCAP metadata records, name -> string map (e.g. ``armsig.source``)."""
    encoded = [(m, json_bytes(m.payload)) for m in messages]
    with atomic_write(path, "wb") as fh:
        writer = checked_writer(fh, PROFILE, LIBRARY)  # type: ignore[arg-type]
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
        for msg, data in encoded:
            writer.add_message(
                channel_id=channel_ids[msg.topic],
                log_time=msg.time_ns if msg.log_time_ns is None else msg.log_time_ns,
                publish_time=msg.time_ns,
                sequence=sequence[msg.topic],
                data=data,
            )
            sequence[msg.topic] += 1
        for name, record in (metadata or {}).items():
            writer.add_metadata(name, record)
        writer.add_metadata(DIGEST_NAME, content_digest((m.topic, d) for m, d in encoded))
        writer.finish()


def refuse_existing_recording(out: Path, force: bool, replacement: str) -> None:
    """A session folder that already holds a recording is never overwritten unless
    ``force``: it may be the only copy of a real one. ``replacement`` names what would
    replace it in the message ("a simulated one")."""
    check_writable(out, "session folder", folder=True)
    recording = out / "recording.mcap"
    if recording.exists() and not force:
        raise ArmsigError(
            f"{out} already holds a recording ({recording})",
            expected="a new session folder",
            fix=f"choose another name, or `--force` to replace {recording} by {replacement}",
        )
