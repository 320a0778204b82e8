"""Read the ``/camera/detections`` channel of a camera recording
(``schemas/mcap/camera_detections.json``, issue 39).

What one message's schema cannot check, refused with one line naming the image: an image
``(sweep, step)`` recorded twice, a sweep or step the plan does not have, ``point_ids``,
``u_px`` and ``v_px`` of different lengths, a point id the recorded target does not have.
The rig's own description (the lens, the target) is checked by :func:`check_camera_rig`.
Pairing with the joint states is the caller's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, RecordingError
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.target import Target, target_from_dict
from pipeline.stages.recording_keys import KEY_FIX, key_text, message_keys, refuse_duplicates

TOPIC = "/camera/detections"


def no_detections() -> dict[str, np.ndarray]:
    """The detection arrays of a recording of another sensor: zero rows."""
    return {
        "detection_sweep": np.zeros(0, np.int64),
        "detection_step": np.zeros(0, np.int64),
        "detection_point": np.zeros(0, np.int64),
        "detection_uv_px": np.zeros((0, 2)),
        "detection_sigma_px": np.zeros(0),
    }


def check_camera_rig(p: Path, rig: dict[str, Any]) -> tuple[Intrinsics, Target]:
    """The recorded lens and target of a camera recording (one-line error if unusable)."""
    try:
        return Intrinsics.from_dict(rig["camera"]), target_from_dict(
            rig["target"], "/rig/description target"
        )
    except ArmsigError as exc:
        raise RecordingError(f"{p}: /rig/description: {exc}") from None


def read_detections(
    p: Path,
    msgs: list[tuple[int, dict[str, Any]]],
    target: Target,
    n_points: dict[int, int | None],
) -> dict[str, np.ndarray]:
    """The ``detection_*`` arrays of :class:`pipeline.stages.recording.Recording`, one row
    per detected point, sorted by ``(sweep, step, point id)``; ``n_points``: sweep id ->
    planned images."""
    payloads = [m for _, m in msgs]
    sweep, step = message_keys(p, TOPIC, payloads, n_points)
    order = np.lexsort((step, sweep))
    payloads, sweep, step = [payloads[k] for k in order], sweep[order], step[order]
    refuse_duplicates(p, TOPIC, sweep, step)
    ids, _ = target.points()
    rows: list[tuple[int, int, np.ndarray, np.ndarray, float]] = []
    for k, m in enumerate(payloads):
        key = key_text(sweep[k], step[k])
        pid = np.asarray(m["point_ids"], np.int64)
        uv = np.stack([np.asarray(m["u_px"], float), np.asarray(m["v_px"], float)], axis=1) if (
            len(m["u_px"]) == len(m["v_px"]) == len(pid)) else None  # fmt: skip
        if uv is None:
            raise RecordingError(
                f"{p}: {TOPIC} {key}: point_ids, u_px and v_px differ in length",
                expected="one u_px and one v_px per point id",
                got=f"{len(pid)}, {len(m['u_px'])} and {len(m['v_px'])}",
                fix=KEY_FIX,
            )
        unknown = pid[~np.isin(pid, ids)]
        if len(unknown):
            raise RecordingError(
                f"{p}: {TOPIC} {key}: point id {int(unknown[0])} is not on the recorded target",
                expected=f"ids of the {target.kind} of /rig/description "
                f"({int(ids.min())}..{int(ids.max())})",
                fix="record the target the detector used",
            )
        rows.append((int(sweep[k]), int(step[k]), pid, uv, float(m["sigma_px"])))
    sizes = [len(r[2]) for r in rows]
    by_id = [np.argsort(r[2], kind="stable") for r in rows]
    return {
        "detection_sweep": np.repeat([r[0] for r in rows], sizes).astype(np.int64),
        "detection_step": np.repeat([r[1] for r in rows], sizes).astype(np.int64),
        "detection_point": np.concatenate([r[2][o] for r, o in zip(rows, by_id, strict=True)]),
        "detection_uv_px": np.concatenate([r[3][o] for r, o in zip(rows, by_id, strict=True)]),
        "detection_sigma_px": np.repeat([r[4] for r in rows], sizes).astype(float),
    }
