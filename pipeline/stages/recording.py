"""Read a session recording (MCAP) into plain arrays, with clear errors.

This is the pipeline's only door to the recording; it knows the channel
contract of ``schemas/mcap/`` and nothing of the simulator.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import RecordingError

TOPICS = ("/rig/description", "/robot/description", "/robot/joint_state", "/sonic/ranges")
_REQUIRED = {
    "/robot/joint_state": ("sweep", "step", "q_commanded", "q_encoder", "units"),
    "/sonic/ranges": ("sweep", "step", "repeat", "ranges_cm"),
    "/robot/description": ("robot", "signature_q", "plan", "mode"),
    "/rig/description": (
        "microphones_cm",
        "rod_sparkers_cm",
        "rod_length_cm",
        "nominal_speed_cm_s",
    ),
}
TOOL_SWEEP = 0  # the tool-probe measurement's sweep id in tables ("tool" in the recording)


@dataclass(frozen=True)
class Recording:
    """Everything a session recording holds.

    ``joint_*`` arrays have one row per commanded configuration, ``cycle_*`` one row
    per digitize cycle; ``sweep`` is the target number, or 0 for the tool probe.
    """

    path: Path
    sha256: str
    rig: dict[str, Any]
    robot: dict[str, Any]
    joint_sweep: np.ndarray  # (K,) int
    joint_step: np.ndarray  # (K,) int
    joint_t_s: np.ndarray  # (K,)
    q_commanded: np.ndarray  # (K, n) deg / cm
    q_encoder: np.ndarray  # (K, n) deg / cm
    cycle_sweep: np.ndarray  # (M,) int
    cycle_step: np.ndarray  # (M,) int
    cycle_repeat: np.ndarray  # (M,) int
    cycle_t_s: np.ndarray  # (M,)
    ranges_cm: np.ndarray  # (M, 5, 4), NaN = no echo


def check_required_fields(
    path: Path,
    msgs: dict[str, list[tuple[int, dict[str, Any]]]],
    required: dict[str, tuple[str, ...]],
) -> None:
    """Raise :class:`RecordingError` naming the first message of ``msgs`` (topic ->
    (log time, decoded JSON)) that lacks a field its channel's schema requires."""
    for topic, keys in required.items():
        for k, (_, m) in enumerate(msgs[topic]):
            absent = [key for key in keys if key not in m]
            if absent:
                raise RecordingError(
                    f"{path}: {topic} message {k} does not match its schema",
                    expected="fields " + ", ".join(keys),
                    got="missing " + ", ".join(absent),
                )


def file_sha256(path: Path) -> str:
    """Content hash of a file (hex)."""
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _sweep_id(value: Any, where: str) -> int:
    if value == "tool":
        return TOOL_SWEEP
    if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
        return value
    raise RecordingError(where, expected="sweep = a target number >= 1 or 'tool'", got=repr(value))


def read_recording(path: str | Path, sha256: str | None = None) -> Recording:
    """Parse ``recording.mcap``; cached per (path, content hash) within a process.

    ``sha256`` is the file's content hash when the caller has already computed it.
    """
    p = Path(path)
    if not p.is_file():
        raise RecordingError(
            f"{p}: no recording",
            expected="a recording.mcap in the session folder",
            fix="record one, or simulate it with `pipeline simulate NAME`",
        )
    return _read_cached(p.resolve(), sha256 or file_sha256(p))


@lru_cache(maxsize=4)
def _read_cached(p: Path, sha: str) -> Recording:
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    msgs: dict[str, list[tuple[int, dict[str, Any]]]] = {t: [] for t in TOPICS}
    with p.open("rb") as fh:
        head = fh.read(8)
        if head[:5] != b"\x89MCAP":
            raise RecordingError(
                f"{p}: not an MCAP file",
                expected="the MCAP magic bytes 89 4D 43 41 50",
                got=repr(head),
                fix="point the pipeline at the session's recording.mcap",
            )
        fh.seek(0)
        try:
            reader = make_reader(fh)
            # File order, then one sort per topic below: the reader's own time-ordered
            # merge costs a heap comparison per message (0.2 s for a session).
            for _schema, channel, message in reader.iter_messages(log_time_order=False):
                if channel.topic not in msgs:
                    continue
                if channel.message_encoding != "json":
                    raise RecordingError(
                        f"{p}: channel {channel.topic} has the wrong encoding",
                        expected="json",
                        got=channel.message_encoding,
                    )
                msgs[channel.topic].append((message.log_time, json.loads(message.data)))
        except RecordingError:
            raise
        except (McapError, EOFError, ValueError, OSError, json.JSONDecodeError) as exc:
            raise RecordingError(
                f"{p}: recording is truncated or corrupt",
                got=f"{type(exc).__name__}: {exc}",
                fix="re-copy the file from the rig, or re-record the session",
            ) from exc
    for topic in TOPICS:
        msgs[topic].sort(key=lambda tm: tm[0])  # stable: equal times keep file order
    missing = [t for t in TOPICS if not msgs[t]]
    if missing:
        raise RecordingError(
            f"{p}: missing channel(s) {', '.join(missing)}",
            expected="channels " + ", ".join(TOPICS),
            fix="record every channel of schemas/mcap/ (see schemas/README.md)",
        )
    check_required_fields(p, msgs, _REQUIRED)
    js = msgs["/robot/joint_state"]
    rg = msgs["/sonic/ranges"]
    try:
        ranges = np.array(
            [
                [[np.nan if v is None else float(v) for v in row] for row in m["ranges_cm"]]
                for _, m in rg
            ],
            float,
        )
        q_cmd = np.array([m["q_commanded"] for _, m in js], float)
        q_enc = np.array([m["q_encoder"] for _, m in js], float)
    except (TypeError, ValueError) as exc:
        raise RecordingError(f"{p}: malformed ranges or joint values", got=str(exc)) from exc
    if ranges.ndim != 3 or ranges.shape[1:] != (5, 4):
        raise RecordingError(
            f"{p}: /sonic/ranges does not match its schema",
            expected="ranges_cm of 5 sparkers x 4 microphones",
            got=f"shape {ranges.shape[1:]}",
        )
    t0 = js[0][0]
    return Recording(
        path=p,
        sha256=sha,
        rig=msgs["/rig/description"][0][1],
        robot=msgs["/robot/description"][0][1],
        joint_sweep=np.array([_sweep_id(m["sweep"], f"{p}: /robot/joint_state") for _, m in js]),
        joint_step=np.array([m["step"] for _, m in js], int),
        joint_t_s=np.array([(t - t0) * 1e-9 for t, _ in js]),
        q_commanded=q_cmd,
        q_encoder=q_enc,
        cycle_sweep=np.array([_sweep_id(m["sweep"], f"{p}: /sonic/ranges") for _, m in rg]),
        cycle_step=np.array([m["step"] for _, m in rg], int),
        cycle_repeat=np.array([m["repeat"] for _, m in rg], int),
        cycle_t_s=np.array([(t - t0) * 1e-9 for t, _ in rg]),
        ranges_cm=ranges,
    )
