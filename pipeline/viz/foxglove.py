"""Foxglove's well-known messages as JSON-ready dicts (schemas in ``schemas/foxglove/``).

Foxglove works in metres: every builder takes centimetres, armsig's unit, and writes
metres (:data:`M_PER_CM`). Field names are those of the published schemas; the
messages are validated against them before they are written (:func:`validate`).
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import SchemaError
from pipeline.schemas import compiled_validator, schema_dir

M_PER_CM = 0.01
#: Schema name (as published) -> file in ``schemas/foxglove/``.
SCHEMAS = {
    "foxglove.FrameTransform": "FrameTransform.json",
    "foxglove.SceneUpdate": "SceneUpdate.json",
    "foxglove.PointCloud": "PointCloud.json",
    "foxglove.CompressedImage": "CompressedImage.json",
    "foxglove.ImageAnnotations": "ImageAnnotations.json",
}
FLOAT64 = 8  # foxglove.NumericType FLOAT64
LINE_STRIP = 0  # foxglove.LineType LINE_STRIP
ZERO_TIME = {"sec": 0, "nsec": 0}
Json = dict[str, Any]
RGBA = tuple[float, float, float, float]


def schema_text(name: str) -> bytes:
    """The published JSON Schema of message ``name`` (``foxglove.FrameTransform``...)."""
    return (schema_dir() / "foxglove" / SCHEMAS[name]).read_bytes()


def validate(name: str, message: Json) -> None:
    """Raise :class:`SchemaError` unless ``message`` is valid against schema ``name``."""
    import fastjsonschema

    try:
        compiled_validator(f"foxglove/{SCHEMAS[name]}")(message)
    except fastjsonschema.JsonSchemaValueException as exc:
        raise SchemaError(f"viz: a {name} message breaks its schema", got=str(exc)) from exc


def vector_m(p_cm: np.ndarray) -> Json:
    """``foxglove.Vector3`` in metres of a point or offset in cm, shape (3,)."""
    x, y, z = (float(v) * M_PER_CM for v in p_cm)
    return {"x": x, "y": y, "z": z}


def quaternion(R: np.ndarray) -> Json:
    """``foxglove.Quaternion`` of a rotation matrix (3, 3)."""
    x, y, z, w = Rotation.from_matrix(R).as_quat()  # scalar last, as Foxglove's
    return {"x": float(x), "y": float(y), "z": float(z), "w": float(w)}


def pose(T_cm: np.ndarray) -> Json:
    """``foxglove.Pose`` of a rigid transform (4, 4) whose translation is in cm."""
    return {"position": vector_m(T_cm[:3, 3]), "orientation": quaternion(T_cm[:3, :3])}


def color(rgba: RGBA) -> Json:
    r, g, b, a = rgba
    return {"r": r, "g": g, "b": b, "a": a}


def stamp(time_ns: int) -> Json:
    """``foxglove.Time`` of ``time_ns``."""
    return {"sec": time_ns // 10**9, "nsec": time_ns % 10**9}


def frame_transform(parent: str, child: str, T_cm: np.ndarray, time_ns: int = 0) -> Json:
    """``foxglove.FrameTransform``: frame ``child`` at ``T_cm`` (4, 4, cm) in ``parent``."""
    p = pose(T_cm)
    return {
        "timestamp": stamp(time_ns),
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": p["position"],
        "rotation": p["orientation"],
    }


def point_cloud(frame: str, points_cm: np.ndarray) -> Json:
    """``foxglove.PointCloud`` of points (m, 3) in cm: fields x, y, z as float64 metres."""
    data = np.ascontiguousarray(points_cm * M_PER_CM, dtype="<f8")
    return {
        "timestamp": ZERO_TIME,
        "frame_id": frame,
        "pose": pose(np.eye(4)),
        "point_stride": 24,
        "fields": [{"name": n, "offset": 8 * k, "type": FLOAT64} for k, n in enumerate("xyz")],
        "data": base64.b64encode(data.tobytes()).decode("ascii"),
    }


def line_strip(points_cm: np.ndarray, rgba: RGBA) -> Json:
    """``foxglove.LinePrimitive`` through points (m, 3) in cm, 2 px wide."""
    return {
        "type": LINE_STRIP,
        "pose": pose(np.eye(4)),
        "thickness": 2.0,
        "scale_invariant": True,
        "points": [vector_m(p) for p in points_cm],
        "color": color(rgba),
        "colors": [],
        "indices": [],
    }


def spheres(points_cm: np.ndarray, size_cm: float, rgba: RGBA) -> list[Json]:
    """``foxglove.SpherePrimitive``s of diameter ``size_cm`` at points (m, 3) in cm."""
    T = np.eye(4)
    out = []
    for p in points_cm:
        T[:3, 3] = p
        out.append({"pose": pose(T), "size": vector_m(np.full(3, size_cm)), "color": color(rgba)})
    return out


def arrow(tail_cm: np.ndarray, direction: np.ndarray, length_cm: float, rgba: RGBA) -> Json:
    """``foxglove.ArrowPrimitive`` from ``tail_cm`` along the unit vector ``direction``."""
    R = np.eye(3)
    if not np.allclose(direction, [1.0, 0.0, 0.0]):  # identity orientation points along +x
        R = Rotation.align_vectors([direction], [[1.0, 0.0, 0.0]])[0].as_matrix()
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, tail_cm
    head = 0.25 * length_cm
    return {
        "pose": pose(T),
        "shaft_length": (length_cm - head) * M_PER_CM,
        "shaft_diameter": 0.04 * length_cm * M_PER_CM,
        "head_length": head * M_PER_CM,
        "head_diameter": 0.1 * length_cm * M_PER_CM,
        "color": color(rgba),
    }


def text(at_cm: np.ndarray, label: str, rgba: RGBA) -> Json:
    """``foxglove.TextPrimitive``: ``label`` facing the camera, 14 px."""
    T = np.eye(4)
    T[:3, 3] = at_cm
    return {
        "pose": pose(T),
        "billboard": True,
        "font_size": 14.0,
        "scale_invariant": True,
        "color": color(rgba),
        "text": label,
    }


def scene_entity(frame: str, entity_id: str, **primitives: list[Json]) -> Json:
    """``foxglove.SceneEntity`` in ``frame`` holding ``primitives`` (arrows=, lines=, ...)."""
    kinds = ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models")
    unknown = set(primitives) - set(kinds)
    if unknown:
        raise SchemaError(f"viz: no primitive kind {sorted(unknown)[0]!r}", expected=str(kinds))
    entity: Json = {
        "timestamp": ZERO_TIME,
        "frame_id": frame,
        "id": entity_id,
        "lifetime": ZERO_TIME,  # zero: stays until replaced
        "frame_locked": False,
        "metadata": [],
    }
    entity.update({k: primitives.get(k, []) for k in kinds})
    return entity


def scene_update(entities: list[Json]) -> Json:
    """``foxglove.SceneUpdate`` adding ``entities``."""
    return {"deletions": [], "entities": entities}


#: foxglove.PointsAnnotationType
POINTS, LINE_LIST = 1, 4


def compressed_image(frame: str, png: bytes, time_ns: int) -> Json:
    """``foxglove.CompressedImage`` of PNG bytes."""
    return {"timestamp": stamp(time_ns), "frame_id": frame,
            "data": base64.b64encode(png).decode("ascii"), "format": "png"}  # fmt: skip


def points_annotation(kind: int, uv_px: np.ndarray, rgba: RGBA, time_ns: int, size: float) -> Json:
    """``foxglove.PointsAnnotation`` of pixels (m, 2) in OpenCV's convention (the top-left
    pixel's centre at (0, 0)); Foxglove's origin is that pixel's top-left corner: + 0.5."""
    return {
        "timestamp": stamp(time_ns), "type": kind,
        "points": [{"x": float(u) + 0.5, "y": float(v) + 0.5} for u, v in uv_px],
        "outline_color": color(rgba), "outline_colors": [], "fill_color": color(rgba),
        "thickness": size,
    }  # fmt: skip


def image_annotations(points: list[Json]) -> Json:
    """``foxglove.ImageAnnotations`` holding ``points`` annotations."""
    return {"circles": [], "points": points, "texts": []}
