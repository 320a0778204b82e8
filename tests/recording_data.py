"""Test helpers: small recordings and their messages (read raw, mutate, write back), and
the session lock held by another run."""

from __future__ import annotations

import contextlib
import io
import json
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.records import Channel, Chunk, Message, Metadata
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from pipeline.rig.recorder import CHANNELS
from pipeline.schemas import mcap_json_schema

DIGEST_NAME = "armsig.content"  # pipeline.contract.digest.DIGEST_NAME
SMALL = {"points": 12, "repeats": 2}


@dataclass
class Raw:
    """One message as recorded: topic, log time (ns), the JSON bytes."""

    topic: str
    log_time: int
    data: bytes

    @property
    def payload(self) -> Any:
        return json.loads(self.data)

    def with_payload(self, payload: Any) -> Raw:
        return Raw(self.topic, self.log_time, json.dumps(payload).encode())


def read_raw(path: Path) -> tuple[list[Raw], dict[str, dict[str, str]]]:
    """Every message in file order and every metadata record, without any check."""
    topics: dict[int, str] = {}
    out: list[Raw] = []
    meta: dict[str, dict[str, str]] = {}
    for record in StreamReader(io.BytesIO(path.read_bytes()), emit_chunks=True).records:
        for r in breakup_chunk(record) if isinstance(record, Chunk) else [record]:
            if isinstance(r, Channel):
                topics[r.id] = r.topic
            elif isinstance(r, Message):
                out.append(Raw(topics[r.channel_id], r.log_time, r.data))
            elif isinstance(r, Metadata):
                meta[r.name] = dict(r.metadata)
    return out, meta


def write_raw(
    path: Path,
    messages: list[Raw],
    metadata: dict[str, dict[str, str]] | None = None,
    data_crcs: bool = True,
    channels: dict[str, str] = CHANNELS,
) -> None:
    """Write messages as given (no digest unless in ``metadata``), as another tool would;
    ``channels``: topic -> schema name (default: a session recording's)."""
    with path.open("wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD, enable_data_crcs=data_crcs)
        w.start(profile="armsig", library="test")
        ids = {}
        for topic, name in channels.items():
            schema = mcap_json_schema(name)
            sid = w.register_schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            ids[topic] = w.register_channel(topic, "json", sid)
        for m in messages:
            w.add_message(ids[m.topic], m.log_time, m.data, m.log_time)
        for name, data in (metadata or {}).items():
            w.add_metadata(name, data)
        w.finish()


def rewrite_keeping_digest(src: Path, dst: Path, messages: list[Raw]) -> None:
    """``messages`` written with ``src``'s original digest: an edit after recording."""
    _, meta = read_raw(src)
    write_raw(dst, messages, {DIGEST_NAME: meta[DIGEST_NAME]})


_MADE: dict[str, Path] = {}


def small_session(factory: Any, seed: int = 2, **options: Any) -> Path:
    """A small simulated session (recording only), made once per test run and options."""
    from pipeline.rig.simulate import SimulationOptions, simulate_session

    key = json.dumps({"seed": seed, **options}, sort_keys=True)
    if key not in _MADE:
        d = factory.mktemp("rec")
        simulate_session(d, SimulationOptions(seed=seed, **{**SMALL, **options}))
        _MADE[key] = d
    return _MADE[key]


@contextlib.contextmanager
def locked_elsewhere(session_dir: Path) -> Iterator[None]:
    """The session lock held by another thread (another run) while the block runs."""
    from pipeline.stages.lock import session_lock

    held, done = threading.Event(), threading.Event()

    def hold() -> None:
        with session_lock(session_dir):
            held.set()
            done.wait(30)

    t = threading.Thread(target=hold)
    t.start()
    try:
        assert held.wait(30), "the other thread never took the lock"
        yield
    finally:
        done.set()
        t.join()
