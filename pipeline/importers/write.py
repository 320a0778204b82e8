"""Write an imported point session: ``SESSION/recording.mcap`` under the session lock."""

from __future__ import annotations

import json
import os
from pathlib import Path

from pipeline.atomic import TEMP_SUFFIX, remove_debris
from pipeline.contract.blocks import BLOCK_TOPIC
from pipeline.contract.channels import POINT_BLOCK_CHANNELS, POINT_CHANNELS, SOURCE_METADATA
from pipeline.contract.digest import file_sha256
from pipeline.errors import ImportFileError, RecordingError
from pipeline.rig.recorder import Message, refuse_existing_recording, write_recording
from pipeline.stages.lock import session_lock
from pipeline.stages.recording import read_recording


def source_metadata(sources: list[Path], fmt: str, map_file: Path | None) -> dict[str, str]:
    """``armsig.source``: the first file's name and SHA-256, the format, the map file's
    SHA-256; with several files, ``files``: each one's name and SHA-256 in order (JSON)."""
    out = {
        "file": sources[0].name,
        "sha256": file_sha256(sources[0]),
        "format": fmt,
        "map_sha256": "" if map_file is None else file_sha256(map_file),
    }
    if len(sources) > 1:
        out["files"] = json.dumps([{"file": p.name, "sha256": file_sha256(p)} for p in sources])
    return out


def write_imported(
    session_dir: Path, messages: list[Message], source: dict[str, str], force: bool
) -> Path:
    """Write the recording atomically (temp file + rename) under the session lock; an
    existing recording is refused unless ``force``. The temp file is read back with
    identify's reader first: a recording identify would refuse (points beyond the
    contract's ±1,000 m, ...) is refused here, and nothing is left. Returns its path."""
    refuse_existing_recording(session_dir, force, "the imported one")
    session_dir.mkdir(parents=True, exist_ok=True)
    recording = session_dir / "recording.mcap"
    with session_lock(session_dir):
        refuse_existing_recording(session_dir, force, "the imported one")
        remove_debris(session_dir)  # the temp files of a killed import (issue 44)
        staged = session_dir / f".{recording.name}.import{TEMP_SUFFIX}"  # debris if killed
        blocks = any(m.topic == BLOCK_TOPIC for m in messages)  # a pose set's (issue 45)
        channels = POINT_BLOCK_CHANNELS if blocks else POINT_CHANNELS
        write_recording(staged, messages, channels, {SOURCE_METADATA: source})
        read_back(staged, source["file"], "check the map's length_unit (mm declared as m?), "
                  "columns and target ids")  # fmt: skip
        os.replace(staged, recording)
    return recording


def read_back(staged: Path, src: str, fix: str) -> None:
    """Read the staged recording with identify's reader (the schemas and the session
    contract); what it would refuse is removed and refused in one line naming ``src``,
    with ``fix``."""
    try:
        read_recording(staged)
    except RecordingError as exc:
        staged.unlink(missing_ok=True)
        what = exc.what.removeprefix(f"{staged.resolve()}: ").removeprefix(f"{staged}: ")
        raise ImportFileError(
            f"{src}: identify would refuse this recording: {what}", got=exc.got, fix=fix
        ) from None
