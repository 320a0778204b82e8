"""Camera intrinsics as ROS ``sensor_msgs/CameraInfo`` YAML (``camera_calibration_parsers``).

The file ``camera_calibration`` writes and ``camera_info_manager`` reads: ``image_width``,
``image_height``, ``camera_name``, ``camera_matrix`` (3 × 3, row-major ``K``),
``distortion_model: plumb_bob`` with ``distortion_coefficients`` ``D = (k1, k2, p1, p2,
k3)`` (OpenCV's order, :mod:`pipeline.sensor.camera`), ``rectification_matrix`` (identity
for a monocular camera) and ``projection_matrix`` ``P = [K | 0]``. Text in, text out: the
writer of a file is the caller's (:func:`pipeline.atomic.write_text_atomic`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.sensor.camera import Intrinsics

DISTORTION_MODEL = "plumb_bob"


def _matrix(rows: int, cols: int, data: Any) -> dict[str, Any]:
    return {"rows": rows, "cols": cols, "data": [float(v) for v in np.ravel(data)]}


def camera_info_text(intrinsics: Intrinsics, camera_name: str = "camera") -> str:
    """The ``camera_info`` YAML of ``intrinsics`` (module docstring)."""
    import yaml

    K = intrinsics.camera_matrix()
    P = np.concatenate([K, np.zeros((3, 1))], axis=1)
    doc = {
        "image_width": int(intrinsics.width_px),
        "image_height": int(intrinsics.height_px),
        "camera_name": camera_name,
        "camera_matrix": _matrix(3, 3, K),
        "distortion_model": DISTORTION_MODEL,
        "distortion_coefficients": _matrix(1, 5, intrinsics.dist_coeffs()),
        "rectification_matrix": _matrix(3, 3, np.eye(3)),
        "projection_matrix": _matrix(3, 4, P),
    }
    return str(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))


def _refuse(source: str, what: str, expected: str, got: object) -> ArmsigError:
    return ArmsigError(
        f"{source}: {what}",
        expected=expected,
        got=repr(got)[:120],
        fix="give the YAML file ROS camera_calibration writes (camera_calibration_parsers)",
    )


def _read_matrix(source: str, doc: dict[str, Any], key: str, shape: tuple[int, int]) -> Any:
    m = doc.get(key)
    data = m.get("data") if isinstance(m, dict) else None
    try:
        values = np.array(data, float)
    except (TypeError, ValueError):
        values = np.zeros(0)
    if values.size != shape[0] * shape[1] or not np.isfinite(values).all():
        raise _refuse(source, f"{key} is not a {shape[0]} × {shape[1]} matrix of numbers",
                      f"{key}: {{rows: {shape[0]}, cols: {shape[1]}, data: [...]}}", m)  # fmt: skip
    return values.reshape(shape)


def intrinsics_from_camera_info(text: str, source: str = "camera_info") -> Intrinsics:
    """The intrinsics of a ``camera_info`` YAML text; ``source`` names it in errors."""
    import yaml

    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise _refuse(source, "not YAML", "a camera_info YAML file", str(exc)) from None
    if not isinstance(doc, dict):
        raise _refuse(source, "not a YAML mapping", "a camera_info YAML file", doc)
    model = doc.get("distortion_model", DISTORTION_MODEL)
    if model not in (DISTORTION_MODEL, "radial-tangential"):
        raise _refuse(source, "unsupported distortion_model", DISTORTION_MODEL, model)
    width, height = doc.get("image_width"), doc.get("image_height")
    if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
        raise _refuse(source, "no image size", "image_width and image_height in px",
                      (width, height))  # fmt: skip
    K = _read_matrix(source, doc, "camera_matrix", (3, 3))
    dist = doc.get("distortion_coefficients", {})
    n = len(dist.get("data", [])) if isinstance(dist, dict) else 0
    D = _read_matrix(source, doc, "distortion_coefficients", (1, n if n in (4, 5) else 5))
    return Intrinsics.from_opencv(K, D.ravel(), width, height)
