"""Recordings carry CRCs, indexes and a content digest; the reader checks them (issue 13)."""

from __future__ import annotations

import io
import random
import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.records import Chunk, DataEnd, MessageIndex, Metadata
from mcap.stream_reader import StreamReader
from recording_data import Raw, read_raw, rewrite_keeping_digest, small_session, write_raw

from pipeline.contract.digest import DIGEST_NAME, content_digest
from pipeline.contract.evaluation import read_evaluation
from pipeline.errors import RecordingError
from pipeline.stages.recording import read_recording

ROOT = Path(__file__).resolve().parent.parent
DIGEST_MSG = "do not match the digest written when it was recorded"


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    return small_session(tmp_path_factory)


def _same(a, b) -> bool:
    return (
        all(
            np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
            for f in (
                "joint_sweep",
                "joint_step",
                "q_encoder",
                "q_commanded",
                "cycle_sweep",
                "cycle_step",
                "cycle_repeat",
                "ranges_cm",
            )
        )
        and a.rig == b.rig
        and a.robot == b.robot
    )


def _one_line_error(path: Path, match: str = "") -> str:
    with pytest.raises(RecordingError, match=match) as exc:
        read_recording(path)
    msg = str(exc.value)
    assert "\n" not in msg and len(msg) < 600, msg
    return msg


@pytest.mark.parametrize("name", ["robot3", "robot7"])
def test_committed_recordings_carry_crcs_indexes_and_digest(name: str) -> None:
    path = ROOT / "sessions" / name / "recording.mcap"
    kinds: dict[str, list] = {}
    for r in StreamReader(io.BytesIO(path.read_bytes()), emit_chunks=True).records:
        kinds.setdefault(type(r).__name__, []).append(r)
    assert all(c.uncompressed_crc != 0 for c in kinds["Chunk"])
    assert kinds["DataEnd"][0].data_section_crc != 0
    assert kinds["MessageIndex"] and kinds["ChunkIndex"]
    (meta,) = [m for m in kinds["Metadata"] if m.name == DIGEST_NAME]
    raw, _ = read_raw(path)
    assert meta.metadata == content_digest((m.topic, m.data) for m in raw)
    read_recording(path)
    read_evaluation(ROOT / "sessions" / name / "evaluation.mcap")


def _offsets(path: Path) -> dict[str, int]:
    """A byte inside the first chunk's compressed data, a message index, the metadata."""
    data = path.read_bytes()
    out: dict[str, int] = {}
    stream = io.BytesIO(data)
    reader = StreamReader(stream, emit_chunks=True)
    for r in reader.records:
        end = stream.tell()
        if isinstance(r, Chunk) and "chunk" not in out:
            out["chunk"] = end - len(r.data) // 2
        elif isinstance(r, MessageIndex) and "index" not in out:
            out["index"] = end - 3
        elif isinstance(r, Metadata):
            out["metadata"] = end - 5
        elif isinstance(r, DataEnd):
            break
    return out


@pytest.mark.parametrize("where", ["chunk", "index", "metadata"])
def test_a_flipped_byte_is_refused_in_one_line(session: Path, tmp_path: Path, where: str) -> None:
    """Before: a flipped byte in a chunk gave a ZstdError traceback or wrong numbers."""
    p = tmp_path / "recording.mcap"
    data = bytearray((session / "recording.mcap").read_bytes())
    data[_offsets(session / "recording.mcap")[where]] ^= 0x10
    p.write_bytes(bytes(data))
    _one_line_error(p, "truncated or corrupt")


def test_seeded_byte_mutations_are_refused_or_harmless(session: Path, tmp_path: Path) -> None:
    """Flips, truncations and splices: a one-line error or the very same recording."""
    src = (session / "recording.mcap").read_bytes()
    good = read_recording(session / "recording.mcap")
    rng = random.Random(13)
    p = tmp_path / "recording.mcap"
    refused = 0
    for k in range(150):
        data = bytearray(src)
        kind = k % 3
        if kind == 0:
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        elif kind == 1:
            del data[rng.randrange(8, len(data)) :]
        else:
            a, b = sorted(rng.sample(range(len(data)), 2))
            data[a:a] = data[b : b + rng.randrange(1, 64)]
        p.write_bytes(bytes(data))
        try:
            rec = read_recording(p)
        except RecordingError as exc:
            assert "\n" not in str(exc)
            refused += 1
        else:
            assert _same(rec, good), f"mutation {k} changed the recording silently"
    # most are refused; a flip in an embedded schema copy (the reader uses schemas/mcap/) or
    # in a string's unused bytes is harmless. 99 of 150 with the point-sensor schemas.
    assert refused > 90


@pytest.mark.parametrize("field", ["record_length", "chunk_uncompressed_size", "chunk_data_length"])
def test_mutated_length_fields_are_refused_without_allocating(
    session: Path, tmp_path: Path, field: str
) -> None:
    data = bytearray((session / "recording.mcap").read_bytes())
    stream = io.BytesIO(bytes(data))
    start = 0
    for r in StreamReader(stream, emit_chunks=True).records:
        if isinstance(r, Chunk):
            break
        start = stream.tell()
    # Chunk record: opcode, length(8), start(8), end(8), uncompressed size(8), crc(4),
    # compression (4 + len), data length (8), data.
    at = {
        "record_length": start + 1,
        "chunk_uncompressed_size": start + 9 + 16,
        "chunk_data_length": start + 9 + 16 + 8 + 4 + 4 + len("zstd"),
    }[field]
    data[at : at + 8] = (2**62).to_bytes(8, "little")
    (tmp_path / "recording.mcap").write_bytes(bytes(data))
    _one_line_error(tmp_path / "recording.mcap", "truncated or corrupt")


def test_recording_without_data_crc_or_digest_still_reads(session: Path, tmp_path: Path) -> None:
    raw, _ = read_raw(session / "recording.mcap")
    write_raw(tmp_path / "recording.mcap", raw, data_crcs=False)
    assert _same(
        read_recording(tmp_path / "recording.mcap"), read_recording(session / "recording.mcap")
    )


def test_an_edited_value_is_refused_by_the_digest(session: Path, tmp_path: Path) -> None:
    raw, _ = read_raw(session / "recording.mcap")
    k = next(i for i, m in enumerate(raw) if m.topic == "/sonic/ranges")
    payload = raw[k].payload
    payload["ranges_cm"][4][0] = round(payload["ranges_cm"][4][0] + 0.01, 2)
    raw[k] = raw[k].with_payload(payload)
    rewrite_keeping_digest(session / "recording.mcap", tmp_path / "recording.mcap", raw)
    _one_line_error(tmp_path / "recording.mcap", DIGEST_MSG)


def test_a_repeated_message_is_refused_by_the_digest(session: Path, tmp_path: Path) -> None:
    raw, _ = read_raw(session / "recording.mcap")
    rewrite_keeping_digest(session / "recording.mcap", tmp_path / "recording.mcap", [*raw, raw[-1]])
    assert "/sonic/ranges" in _one_line_error(tmp_path / "recording.mcap", DIGEST_MSG)


def test_new_log_times_are_not_an_edit(session: Path, tmp_path: Path) -> None:
    raw, _ = read_raw(session / "recording.mcap")
    times = [m.log_time for m in raw]
    random.Random(1).shuffle(times)
    moved = [Raw(m.topic, t, m.data) for m, t in zip(raw, times, strict=True)]
    rewrite_keeping_digest(session / "recording.mcap", tmp_path / "recording.mcap", moved)
    assert _same(
        read_recording(tmp_path / "recording.mcap"), read_recording(session / "recording.mcap")
    )


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"null", "not a JSON object"),
        (b"[1, 2]", "not a JSON object"),
        (b"NaN", "not valid JSON"),
        (b'{"sweep": NaN}', "not valid JSON"),
        (b'{"sweep": -Infinity}', "not valid JSON"),
        (b"[" * 100000 + b"]" * 100000, "not valid JSON"),
        (b'{"sweep": "\xff"}', "not valid JSON"),
        (b'{"sweep": 1', "not valid JSON"),
    ],
)
def test_undecodable_messages_are_one_line_errors(
    session: Path, tmp_path: Path, data: bytes, match: str
) -> None:
    raw, _ = read_raw(session / "recording.mcap")
    k = next(i for i, m in enumerate(raw) if m.topic == "/robot/joint_state")
    raw[k] = Raw(raw[k].topic, raw[k].log_time, data)
    write_raw(tmp_path / "recording.mcap", raw)
    _one_line_error(tmp_path / "recording.mcap", match)


def test_evaluation_recording_is_checked_too(tmp_path: Path) -> None:
    src = ROOT / "sessions/robot3/evaluation.mcap"
    data = bytearray(src.read_bytes())
    data[_offsets(src)["chunk"]] ^= 0x01
    (tmp_path / "evaluation.mcap").write_bytes(bytes(data))
    with pytest.raises(RecordingError, match="truncated or corrupt"):
        read_evaluation(tmp_path / "evaluation.mcap")
    shutil.copy(src, tmp_path / "ok.mcap")
    assert read_evaluation(tmp_path / "ok.mcap").teach
