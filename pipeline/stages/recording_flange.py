"""Read a recording of flange poses and no joint readings (issue 40): an imported image set
whose robot reported the flange's pose at each image (``schemas/mcap/flange_pose.json``).

Such a session cannot calibrate the arm; it calibrates the camera (its intrinsics and
both hand-eye transforms, :mod:`pipeline.refine.hand_eye`). What one message's schema
cannot check, refused with one line naming the key: a flange pose recorded twice, a
quaternion that is not a rotation, an image's detections without its flange pose.
The images' references (``/camera/images``: file, SHA-256, why dropped) are read too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import RecordingError
from pipeline.stages.recording_camera import check_camera_rig, read_detections
from pipeline.stages.recording_keys import KEY_FIX, key_text, message_keys, refuse_duplicates
from pipeline.sweeps import POSES_SWEEP

FLANGE_TOPIC, IMAGES_TOPIC = "/robot/flange_pose", "/camera/images"
#: A recorded quaternion's norm may differ from 1 by this much: the importer writes
#: scipy's unit quaternions (1e-16); a text file's rounding is refused at import (1e-3).
QUAT_NORM_TOL = 1e-3


def _sorted_keys(p: Path, topic: str, msgs: list[tuple[int, dict[str, Any]]]) -> tuple[
    list[dict[str, Any]], np.ndarray, np.ndarray
]:  # fmt: skip
    """The payloads of ``topic`` sorted by (sweep, step), their keys; a key twice refused."""
    payloads = [m for _, m in msgs]
    sweep, step = message_keys(p, topic, payloads, {POSES_SWEEP: None})
    order = np.lexsort((step, sweep))
    payloads, sweep, step = [payloads[k] for k in order], sweep[order], step[order]
    refuse_duplicates(p, topic, sweep, step)
    return payloads, sweep, step


def flange_arrays(p: Path, msgs: dict[str, list[tuple[int, dict[str, Any]]]]) -> dict[str, Any]:
    """The ``flange_*``, ``image_*`` and ``detection_*`` arrays of
    :class:`pipeline.stages.recording.Recording` of a flange-pose recording."""
    from scipy.spatial.transform import Rotation

    rig = msgs["/rig/description"][0][1]
    _, target = check_camera_rig(p, rig)
    payloads, sweep, step = _sorted_keys(p, FLANGE_TOPIC, msgs[FLANGE_TOPIC])
    wxyz = np.array([m["orientation_wxyz"] for m in payloads], float).reshape(-1, 4)
    norm = np.linalg.norm(wxyz, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
    if len(bad):
        raise RecordingError(
            f"{p}: {FLANGE_TOPIC} {key_text(sweep[bad[0]], step[bad[0]])}: the quaternion is "
            "not a rotation", expected=f"norm 1 ± {QUAT_NORM_TOL:g}", got=f"{norm[bad[0]]:g}",
            fix=KEY_FIX,
        )  # fmt: skip
    T = np.tile(np.eye(4), (len(payloads), 1, 1))
    q = wxyz / norm[:, None]
    T[:, :3, :3] = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    T[:, :3, 3] = np.array([m["position_cm"] for m in payloads], float).reshape(-1, 3)
    det = read_detections(p, msgs["/camera/detections"], target, {POSES_SWEEP: None})
    ds, dk = det["detection_sweep"], det["detection_step"]
    orphan = np.flatnonzero(~np.isin(ds * (1 << 21) + dk, sweep * (1 << 21) + step))
    if len(orphan):
        raise RecordingError(
            f"{p}: /camera/detections image {key_text(ds[orphan[0]], dk[orphan[0]])} has no "
            f"{FLANGE_TOPIC}", expected="the flange pose of every image, same (sweep, step)",
            fix=KEY_FIX,
        )  # fmt: skip
    return {
        "flange_sweep": sweep,
        "flange_step": step,
        "flange_in_base_cm": T,
        **image_arrays(p, msgs),
        **det,
    }


def image_arrays(p: Path, msgs: dict[str, list[tuple[int, dict[str, Any]]]]) -> dict[str, Any]:
    """The ``image_*`` arrays of :class:`pipeline.stages.recording.Recording`: the images
    the recording references (``/camera/images``), sorted by key; none: zero rows."""
    images, i_sweep, i_step = _sorted_keys(p, IMAGES_TOPIC, msgs[IMAGES_TOPIC])
    return {
        "image_sweep": i_sweep,
        "image_step": i_step,
        "image_file": np.array([m["file"] for m in images], str),
        "image_sha256": np.array([m["sha256"] for m in images], str),
        "image_dropped": np.array([m["dropped"] for m in images], str),
    }
