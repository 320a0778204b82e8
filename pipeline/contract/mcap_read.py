"""Read every message of an MCAP recording, its integrity and its schemas checked.

One linear pass of the mcap library's ``StreamReader`` over the file's bytes:

- chunk CRCs and the data-section CRC (``DataEnd``) are validated. The
  ``SeekingReader`` would validate chunk CRCs only: it reaches the chunks through
  the summary's index and never reads the data section as a whole, so message
  indexes and metadata would go unchecked. Every message is read anyway, so the
  linear pass costs no more (measured on robot3: see ``docs/rig.md``). A file
  without a data-section CRC (0, as written before issue 13) still reads;
- every record length, and every length inside a record, is bounded by the file
  size: records are read from the bytes in memory, which never hand out more than
  they hold, and a chunk may not inflate beyond :data:`MAX_CHUNK_BYTES`;
- the ``armsig.content`` digest (:mod:`pipeline.contract.digest`) is verified when
  present;
- messages of the known channels are decoded as JSON objects (``NaN`` and
  ``Infinity`` are not JSON and are refused) and validated against their schema.

Every failure is one :class:`~pipeline.errors.RecordingError`.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.contract.batch_schema import all_valid
from pipeline.contract.channels import upgrade_legacy, validator
from pipeline.contract.digest import COUNT_PREFIX, DIGEST_NAME, content_digest
from pipeline.errors import RecordingError, one_line
from pipeline.schemas import mcap_json_schema, strict_json

#: Largest uncompressed chunk: 256 times the 1 MiB chunks armsig writes (a mutated
#: size field must not make the reader allocate gigabytes).
MAX_CHUNK_BYTES = 1 << 28
_MAGIC_PREFIX = b"\x89MCAP"
_SHOWN = 120  # characters of a bad value shown in an error
#: Channels with this many messages are first validated as a whole (batch_schema).
_BATCH = 50


@dataclass(frozen=True)
class McapContent:
    """The messages of a recording's known channels and its metadata records.

    ``messages``: topic -> (measurement time in ns, JSON object), in file order: the
    MCAP ``publish_time`` (when the rig measured the message), or the ``log_time`` (when a
    logger wrote it) on a channel whose publish times are not set (0), as the MCAP
    specification allows; ``metadata``: name -> key/value pairs.
    """

    path: Path
    messages: dict[str, list[tuple[int, dict[str, Any]]]]
    metadata: dict[str, dict[str, str]]


def read_mcap(path: Path, channels: Mapping[str, str], fix: str) -> McapContent:
    """Read ``path``; ``channels``: known topic -> schema name; ``fix``: advice on corruption."""
    from fastjsonschema import JsonSchemaValueException

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read the recording", got=str(exc)) from exc
    if data[:5] != _MAGIC_PREFIX:
        raise RecordingError(
            f"{path}: not an MCAP file",
            expected="the MCAP magic bytes 89 4D 43 41 50",
            got=repr(data[:8]),
            fix="point the pipeline at the session's recording.mcap",
        )
    raw, encodings, metadata = _records(path, data, fix)
    recorded = metadata.get(DIGEST_NAME)
    if recorded is not None:
        _check_digest(path, recorded, content_digest((t, d) for t, _, _, d in raw))
    for topic in channels:
        if encodings.get(topic, "json") != "json":
            raise RecordingError(
                f"{path}: channel {topic} has the wrong encoding",
                expected="json",
                got=encodings[topic],
            )
    messages: dict[str, list[tuple[int, dict[str, Any]]]] = {t: [] for t in channels}
    index: dict[str, list[int]] = {t: [] for t in channels}
    unset = {t for t, _, publish_time, _ in raw if publish_time == 0}
    for k, (topic, log_time, publish_time, payload_bytes) in enumerate(raw):
        if topic in messages:  # another channel: in the digest, not read
            payload = _decode(path, topic, k, payload_bytes)
            upgrade_legacy(topic, payload)
            messages[topic].append((log_time if topic in unset else publish_time, payload))
            index[topic].append(k)
    for topic, schema_name in channels.items():
        payloads = [m for _, m in messages[topic]]
        if len(payloads) >= _BATCH and all_valid(mcap_json_schema(schema_name), payloads):
            continue
        check = validator(schema_name)
        for k, payload in zip(index[topic], payloads, strict=True):
            try:
                check(payload)
            except JsonSchemaValueException as exc:
                raise RecordingError(
                    f"{path}: {topic} message {k} does not match schemas/mcap/{schema_name}.json",
                    got=_one_line(exc.message),
                    fix="repair the rig's writer; the schema is the contract (schemas/README.md)",
                ) from exc
    return McapContent(path, messages, metadata)


def _records(
    path: Path, data: bytes, fix: str
) -> tuple[list[tuple[str, int, int, bytes]], dict[str, str], dict[str, dict[str, str]]]:
    """Messages (topic, log time, publish time, data) in file order, topic -> encoding,
    metadata."""
    import zstandard
    from mcap.exceptions import McapError
    from mcap.records import Channel, Chunk, DataEnd, Message, Metadata
    from mcap.stream_reader import StreamReader, breakup_chunk

    raw: list[tuple[str, int, int, bytes]] = []
    topics: dict[int, str] = {}
    encodings: dict[str, str] = {}
    metadata: dict[str, dict[str, str]] = {}
    reader = StreamReader(
        io.BytesIO(data), emit_chunks=True, validate_crcs=True, record_size_limit=len(data)
    )
    try:
        for record in reader.records:
            if isinstance(record, DataEnd):
                break  # the summary section repeats what the data section holds
            if isinstance(record, Chunk):
                _check_chunk(record)
                inner = breakup_chunk(record, validate_crc=True)
            else:
                inner = [record]
            for r in inner:
                if isinstance(r, Channel):
                    topics[r.id] = r.topic
                    encodings[r.topic] = r.message_encoding
                elif isinstance(r, Message):
                    if r.channel_id not in topics:
                        raise McapError(f"message on unknown channel id {r.channel_id}")
                    raw.append((topics[r.channel_id], r.log_time, r.publish_time, r.data))
                elif isinstance(r, Metadata):
                    if r.name in metadata:
                        raise McapError(f"metadata {r.name!r} written twice")
                    metadata[r.name] = dict(r.metadata)
        else:
            raise McapError("no DataEnd record")
    except (
        McapError,
        zstandard.ZstdError,
        struct.error,
        ValueError,  # CRCValidationError, UnicodeDecodeError of a name
        RuntimeError,  # lz4, RecursionError
        LookupError,
        OverflowError,
        MemoryError,
        EOFError,
        OSError,
        TypeError,
    ) as exc:
        raise RecordingError(
            f"{path}: recording is truncated or corrupt",
            got=_one_line(f"{type(exc).__name__}: {exc}"),
            fix=fix,
        ) from exc
    return raw, encodings, metadata


def _check_chunk(chunk: Any) -> None:
    """Refuse a chunk whose declared size would make decompression allocate too much."""
    import zstandard
    from mcap.exceptions import McapError

    size = chunk.uncompressed_size
    if size > MAX_CHUNK_BYTES:
        raise McapError(f"chunk declares {size} bytes uncompressed, over {MAX_CHUNK_BYTES}")
    if chunk.compression == "zstd":
        # zstd allocates what its frame header declares, not what the chunk says.
        declared = zstandard.get_frame_parameters(chunk.data).content_size
        if declared not in (size, zstandard.CONTENTSIZE_UNKNOWN):
            raise McapError(f"chunk of {size} bytes holds a zstd frame of {declared}")
    elif chunk.compression == "lz4":
        import lz4.frame

        declared = lz4.frame.get_frame_info(chunk.data)["content_size"]
        if declared not in (size, 0):
            raise McapError(f"chunk of {size} bytes holds an lz4 frame of {declared}")


def _check_digest(path: Path, recorded: dict[str, str], actual: dict[str, str]) -> None:
    def facts(d: dict[str, str]) -> dict[str, str]:
        return {k: v for k, v in d.items() if k == "sha256" or k.startswith(COUNT_PREFIX)}

    if recorded.get("algorithm") != actual["algorithm"]:
        raise RecordingError(
            f"{path}: unknown digest algorithm in metadata {DIGEST_NAME}",
            expected=actual["algorithm"],
            got=_one_line(repr(recorded.get("algorithm"))),
        )
    want, got = facts(recorded), facts(actual)
    if want != got:
        counts = {k: (want.get(k), got.get(k)) for k in {*want, *got} - {"sha256"}}
        differ = sorted(
            f"{k[len(COUNT_PREFIX) :]} {a} -> {b}" for k, (a, b) in counts.items() if a != b
        )
        raise RecordingError(
            f"{path}: the recording's messages do not match the digest written when it was "
            "recorded: edited or corrupted after recording",
            got="message counts " + ", ".join(differ) if differ else "other message contents",
            fix="use the file as the rig wrote it, or re-record the session",
        )


def _decode(path: Path, topic: str, k: int, data: bytes) -> dict[str, Any]:
    try:
        payload = strict_json(data.decode("utf-8"))  # JSON is UTF-8 (RFC 8259)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise RecordingError(
            f"{path}: {topic} message {k} is not valid JSON",
            got=_one_line(f"{type(exc).__name__}: {exc}"),
            fix="repair the rig's writer (messages are JSON, schemas/README.md)",
        ) from exc
    if not isinstance(payload, dict):
        raise RecordingError(
            f"{path}: {topic} message {k} is not a JSON object",
            got=_one_line(repr(payload)),
            fix="repair the rig's writer (schemas/mcap/ describes each message)",
        )
    return payload


def _one_line(text: str) -> str:
    return one_line(text, _SHOWN)
