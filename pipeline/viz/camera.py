"""The messages of a camera session's ``viz.mcap`` (issue 40): what the camera saw and
where the fit puts the camera and the target.

One image per second of log time (image ``k`` of the fit at ``k + 1`` s), so that
Foxglove plays the session image by image:

- ``/camera/image`` (``foxglove.CompressedImage``, frame ``camera``): the PNG the
  recording references by SHA-256 (a rendered or imported image), when it has one;
- ``/camera/annotations`` (``foxglove.ImageAnnotations``): the detected corners (green),
  the fit's reprojected ones (red: detected plus the ``camera_residuals`` stage's
  residual) and the residual vectors drawn ``RESIDUAL_SCALE`` times their length
  (yellow), in Foxglove's pixel convention (OpenCV's + 0.5 px);
- ``/tf``: the fixed body at the sensor frame's origin (the camera for eye-to-hand, the
  target for eye-in-hand, at time 0) and the body on the flange where the fitted chain
  puts it at the image's joint readings (``camera_fit``'s model, at the image's time);
- ``/camera/scene`` (``foxglove.SceneUpdate``, time 0): the camera's frustum (the fitted
  lens's image corners, undistorted, out to the
  farthest target seen) in frame
  ``camera`` and the target's outline and points in frame ``target``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.viz import foxglove as fg
from pipeline.viz.scene import SENSOR, TF_TOPIC, VizMessage

IMAGE_TOPIC, ANNOTATION_TOPIC, SCENE_TOPIC = "/camera/image", "/camera/annotations", "/camera/scene"
CAMERA, TARGET = "camera", "target"
IMAGE_NS = 10**9  # one image per second of log time
RESIDUAL_SCALE = 10.0  # residual vectors drawn ten times their length
DETECTED: fg.RGBA = (0.17, 0.63, 0.17, 1.0)
REPROJECTED: fg.RGBA = (0.84, 0.15, 0.16, 1.0)
RESIDUAL: fg.RGBA = (0.74, 0.74, 0.13, 1.0)
FRUSTUM: fg.RGBA = (0.12, 0.47, 0.71, 1.0)


def camera_messages(sdir: Path, tables: dict[str, pa.Table], rec: Any) -> list[VizMessage]:
    """The messages (module docstring) of the camera session in ``sdir`` from its
    committed stage tables (``session``, ``joints``, ``camera_fit``,
    ``camera_residuals``) and its recording ``rec``."""
    from pipeline.refine.camera_fit import tool_poses
    from pipeline.stages.camera_fit import fit_pixels, fitted_model
    from pipeline.stages.frames import readings_at
    from pipeline.stages.session import session_robot
    from pipeline.sweeps import POSES_SWEEP
    from pipeline.units import joints_to_internal

    session, fit = tables["session"], tables["camera_fit"]
    rig = json.loads(session.column("rig_json")[0].as_py())
    robot = session_robot(session)
    model, x, intrinsics, q_sig = fitted_model(fit, robot)
    images = fit_pixels(rig, tables["detections"])[0]
    q = readings_at(tables["joints"], POSES_SWEEP, images, robot.n_joints, robot.prismatic)
    tool = tool_poses(model, x, joints_to_internal(q, robot.prismatic), q_sig)
    fixed, moving = bodies(rig["setup"])
    out = [VizMessage(TF_TOPIC, "foxglove.FrameTransform",
                      fg.frame_transform(SENSOR, fixed, np.eye(4)))]  # fmt: skip
    out += [VizMessage(TF_TOPIC, "foxglove.FrameTransform",
                       fg.frame_transform(SENSOR, moving, T, image_time(k)), image_time(k))
            for k, T in enumerate(tool)]  # fmt: skip
    depth = float(np.max(np.linalg.norm(tool[:, :3, 3], axis=1)))  # the farthest target
    out += image_messages(images, tables["camera_residuals"], rec)
    out.append(scene_message(intrinsics, rig, depth))
    return in_time_order(out)


def bodies(setup: str) -> tuple[str, str]:
    """The frames of (the fixed body, the body on the flange) of a set-up."""
    return (CAMERA, TARGET) if setup == "eye-to-hand" else (TARGET, CAMERA)


def image_time(k: int) -> int:
    """Log time (ns) of the fit's image ``k``: one image per second."""
    return (k + 1) * IMAGE_NS


def in_time_order(messages: list[VizMessage]) -> list[VizMessage]:
    """``messages`` by log time (stable: each topic keeps its order)."""
    return sorted(messages, key=lambda m: m.time_ns)


def image_messages(images: np.ndarray, residuals: pa.Table, rec: Any) -> list[VizMessage]:
    """Per image of the fit (``images``: their steps, in the fit's order; image ``k`` at
    :func:`image_time`): the PNG the recording references, when it has one, and the
    annotations (module docstring) from the ``camera_residuals`` table."""
    from pipeline.stages.image_inputs import image_refs

    res = residuals.to_pydict()
    r_image = np.asarray(res["image"])
    uv = np.stack([res["u_px"], res["v_px"]], axis=1)
    duv = np.stack([res["du_px"], res["dv_px"]], axis=1)
    refs = image_refs(rec)
    files = {int(s): f for s, f, h in zip(refs.step, refs.file, refs.recorded, strict=True) if h}
    out = []
    for k, step in enumerate(images):
        t = image_time(k)
        if refs.folder is not None and int(step) in files:
            png = (refs.folder / files[int(step)]).read_bytes()
            out.append(VizMessage(IMAGE_TOPIC, "foxglove.CompressedImage",
                                  fg.compressed_image(CAMERA, png, t), t))  # fmt: skip
        m = r_image == step
        seen, again = uv[m], uv[m] + duv[m]
        vectors = np.stack([seen, seen + RESIDUAL_SCALE * duv[m]], axis=1).reshape(-1, 2)
        out.append(VizMessage(ANNOTATION_TOPIC, "foxglove.ImageAnnotations",
                              fg.image_annotations([
                                  fg.points_annotation(fg.POINTS, seen, DETECTED, t, 6.0),
                                  fg.points_annotation(fg.POINTS, again, REPROJECTED, t, 4.0),
                                  fg.points_annotation(fg.LINE_LIST, vectors, RESIDUAL, t, 1.0),
                              ]), t))  # fmt: skip
    return out


def scene_message(
    intrinsics: np.ndarray, rig: dict[str, Any], depth_cm: float, *extra: fg.Json
) -> VizMessage:
    """``/camera/scene`` (time 0): the frustum out to ``depth_cm``, the target and
    ``extra`` entities."""
    entities = [frustum(intrinsics, rig["camera"], depth_cm), target_entity(rig["target"])]
    return VizMessage(SCENE_TOPIC, "foxglove.SceneUpdate", fg.scene_update([*entities, *extra]))


def frustum(intrinsics: np.ndarray, stated: dict[str, Any], depth_cm: float) -> fg.Json:
    """The camera's frustum (frame ``camera``): its optical centre to the image's corners
    at ``depth_cm`` along the optical axis (the fitted pinhole), and the image's outline."""
    fx, fy, cx, cy = intrinsics[:4]
    w, h = float(stated["width_px"]), float(stated["height_px"])
    px = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    corners = np.stack([(px[:, 0] - cx) / fx, (px[:, 1] - cy) / fy, np.ones(4)], 1) * depth_cm
    lines = [fg.line_strip(np.array([np.zeros(3), c]), FRUSTUM) for c in corners]
    lines.append(fg.line_strip(np.vstack([corners, corners[:1]]), FRUSTUM))
    return fg.scene_entity(CAMERA, "frustum", lines=lines)


def target_entity(target_dict: dict[str, Any]) -> fg.Json:
    """The target's points and outline (frame ``target``, its own frame)."""
    from pipeline.sensor.target import target_from_dict

    _, local = target_from_dict(target_dict, "target").points()
    lo, hi = local.min(axis=0), local.max(axis=0)
    outline = np.array([[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0],
                        [lo[0], hi[1], 0], [lo[0], lo[1], 0]])  # fmt: skip
    return fg.scene_entity(TARGET, "target", lines=[fg.line_strip(outline, FRUSTUM)],
                           spheres=fg.spheres(local, 0.6, DETECTED))  # fmt: skip


def check_fresh(sdir: Path) -> None:
    """Refuse a camera session whose identification is not fresh (one line): each stage
    at the parameters it was identified with (``identify --param`` too)."""
    from pipeline.stages.runner import identification_modules, status

    for s in status(sdir, modules=identification_modules(sdir), as_recorded=True):
        if s.state != "fresh":
            raise StageError(f"{sdir}: stage {s.name} is {s.state}: {s.reason}",
                             fix=f"run `pipeline identify {sdir}`")  # fmt: skip
