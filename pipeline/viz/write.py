"""``pipeline viz``: write a session's ``viz.mcap`` for Foxglove's 3-D panel.

Reads the session's signature (refused when stale) and its committed, checked
``positions`` and ``features`` tables under the session lock; validates every
message against its published Foxglove schema; writes the file atomically. An
existing file at the output path is replaced only when ``pipeline viz`` wrote it.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from mcap.exceptions import McapError
from mcap.reader import make_reader

from pipeline import __version__
from pipeline.atomic import atomic_write, check_writable
from pipeline.contract.mcap_write import checked_writer, json_bytes
from pipeline.errors import ArmsigError, StageError
from pipeline.robots.fk import outside_limits
from pipeline.signature.file import FILE_NAME
from pipeline.signature.session import load_session_signature
from pipeline.stages.lock import session_lock
from pipeline.stages.recording import read_recording
from pipeline.stages.runner import session_folder, stage_path
from pipeline.stages.tables import check_table
from pipeline.units import joints_to_boundary, joints_to_internal
from pipeline.viz import foxglove as fg
from pipeline.viz.scene import (
    SENSOR,
    VizMessage,
    feature_messages,
    frame_messages,
    point_messages,
)

VIZ_NAME = "viz.mcap"
LIBRARY = "armsig-viz"  # the header's library: marks a file this command may replace
METADATA_NAME = "armsig.viz"


@dataclass(frozen=True)
class VizResult:
    """The file written, its messages per topic, the configuration shown (deg / cm) and
    the frame to display it in."""

    path: Path
    topics: dict[str, int]
    configuration: list[float]
    outside_limits: list[str]
    display_frame: str = SENSOR


def _checked(sdir: Path, name: str) -> pa.Table:
    """A committed stage table, read back and checked (schema, content hash)."""
    checked = check_table(stage_path(sdir, name), name)
    if checked.table is None:
        raise StageError(
            f"{stage_path(sdir, name)}: {checked.problem}", fix=f"run `pipeline identify {sdir}`"
        )
    return checked.table


def _written_by_viz(path: Path) -> bool:
    """Whether ``path`` is an MCAP file whose header names this command as its writer."""
    try:
        with path.open("rb") as fh:
            return make_reader(fh).get_header().library.startswith(LIBRARY)
    except (McapError, OSError, ValueError, struct.error):
        return False


def _refuse_foreign(path: Path) -> None:
    if path.exists() and not (path.is_file() and _written_by_viz(path)):
        raise ArmsigError(
            f"{path} exists and was not written by `pipeline viz`",
            expected="a new path or a viz.mcap to replace",
            fix="remove it, or give another --out",
        )


def _configuration(q: list[float] | None, default: np.ndarray, names: list[str]) -> np.ndarray:
    """Joint values (deg / cm) to show: ``q``, or the signature configuration."""
    if q is None:
        return default
    values = np.asarray(q, float)
    if values.shape != default.shape:
        raise ArmsigError(
            "--q must hold one value per joint",
            expected=f"{len(names)} values ({', '.join(names)})",
            got=f"{values.size} values",
        )
    if not np.isfinite(values).all():
        raise ArmsigError("--q must hold finite numbers", got=" ".join(f"{v:g}" for v in q))
    return values


def write_mcap(path: Path, messages: list[VizMessage], metadata: dict[str, str]) -> None:
    """Write ``messages`` (JSON, schemas embedded as published) to ``path`` atomically."""
    with atomic_write(path, "wb") as fh:
        writer = checked_writer(fh, "", f"{LIBRARY} {__version__}")  # type: ignore[arg-type]
        schema_ids = {
            name: writer.register_schema(name, "jsonschema", fg.schema_text(name))
            for name in sorted({m.schema for m in messages})
        }
        channels: dict[str, int] = {}
        sequence: dict[str, int] = {}
        for m in messages:
            if m.topic not in channels:
                channels[m.topic] = writer.register_channel(m.topic, "json", schema_ids[m.schema])
                sequence[m.topic] = 0
            writer.add_message(
                channels[m.topic], m.time_ns, json_bytes(m.payload), m.time_ns, sequence[m.topic]
            )
            sequence[m.topic] += 1
        writer.add_metadata(METADATA_NAME, metadata)
        writer.finish()


def viz(
    session_dir: str | Path, q: list[float] | None = None, out: str | Path | None = None
) -> VizResult:
    """Write the session's frames (signature and design model at joint values ``q``,
    deg / cm, default the signature configuration q^s), fitted features and measured
    positions to ``out`` (default ``SESSION/viz.mcap``), in metres."""
    sdir = session_folder(session_dir)
    path = sdir / VIZ_NAME if out is None else check_writable(out, "--out")
    with session_lock(sdir):
        rec = read_recording(sdir / "recording.mcap")
        if rec.sensor == "camera":
            return _camera_viz(sdir, path, rec, q)
        sig = load_session_signature(sdir / FILE_NAME)
        pris = sig.prismatic
        names = [j.name for j in sig.robot.joints]
        q_s = joints_to_boundary(np.asarray(sig.chain.joint_offsets), pris)
        q_b = _configuration(q, q_s, names)
        messages = [
            *frame_messages(sig, joints_to_internal(q_b, pris)),
            *feature_messages(sig, _checked(sdir, "features")),
            *point_messages(_checked(sdir, "positions")),
        ]
        for m in messages:
            fg.validate(m.schema, m.payload)
        _refuse_foreign(path)
        units = [j.unit for j in sig.robot.joints]
        write_mcap(
            path,
            messages,
            {
                "session": sdir.name,
                "robot": sig.robot.name,
                "configuration": json.dumps([float(v) for v in q_b]),
                "configuration_units": json.dumps(units),
                "length_unit": "m",
                "package_version": __version__,
            },
        )
    outside = list(outside_limits(sig.robot, q_b))
    return VizResult(path, _topics(messages), [float(v) for v in q_b], outside)


def _topics(messages: list[VizMessage]) -> dict[str, int]:
    topics: dict[str, int] = {}
    for m in messages:
        topics[m.topic] = topics.get(m.topic, 0) + 1
    return topics


def _camera_viz(sdir: Path, path: Path, rec: Any, q: list[float] | None) -> VizResult:
    """A camera session's ``viz.mcap`` (:mod:`pipeline.viz.camera`; a session of flange
    poses without joints: :mod:`pipeline.viz.hand_eye`), under the lock."""
    from pipeline.stages.recording import FLANGE_KIND
    from pipeline.viz.camera import camera_messages, check_fresh
    from pipeline.viz.hand_eye import BASE, hand_eye_messages

    if q is not None:
        raise ArmsigError("--q does not apply to a camera session (its images' own joint "
                          "readings or flange poses place the camera and the target)",
                          fix="drop --q")  # fmt: skip
    check_fresh(sdir)
    flange = rec.kind == FLANGE_KIND
    poses = "flange_poses" if flange else "joints"
    names = ("session", poses, "detections", "camera_fit", "camera_residuals")
    tables = {n: _checked(sdir, n) for n in names}
    messages = hand_eye_messages(tables, rec) if flange else camera_messages(sdir, tables, rec)
    for m in messages:
        fg.validate(m.schema, m.payload)
    _refuse_foreign(path)
    robot = rec.robot["robot"]["name"] if "robot" in rec.robot else ""
    frame = BASE if flange else SENSOR
    write_mcap(path, messages, {"session": sdir.name, "robot": str(robot),
                                "setup": str(rec.rig["setup"]), "length_unit": "m",
                                "display_frame": frame,
                                "package_version": __version__})  # fmt: skip
    return VizResult(path, _topics(messages), [], [], frame)
