"""The messages of ``viz.mcap`` of a camera session of flange poses without joints (issue
40): the joint camera session's images, annotations, frustum and target
(:mod:`pipeline.viz.camera`), placed by the recorded flange poses and the fitted hand-eye
transforms instead of the chain's forward kinematics.

Frames (display frame ``base``, the robot's base the flange poses are given in):

- ``base`` → the fixed body (``camera`` eye-to-hand, ``target`` eye-in-hand) where the
  calibration puts it (``camera_fit``'s ``fixed_in_base_cm``; time 0);
- ``base`` → ``flange`` at each image's recorded pose (``flange_poses``; at the image's
  time, one image per second as :func:`pipeline.viz.camera.image_time`);
- ``flange`` → the body on the flange (``target`` eye-to-hand, ``camera`` eye-in-hand)
  where the calibration puts it (``tool_in_flange_cm``; time 0).

``/camera/scene`` adds the recorded flange positions (entity ``flange_poses``, frame
``base``: a sphere at each, joined in measurement order).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.kinematics.transforms import invert_transform
from pipeline.viz import foxglove as fg
from pipeline.viz.camera import (
    FRUSTUM,
    bodies,
    image_messages,
    image_time,
    in_time_order,
    scene_message,
)
from pipeline.viz.scene import TF_TOPIC, VizMessage

BASE, FLANGE = "base", "flange"
FLANGE_COLOUR: fg.RGBA = (0.58, 0.40, 0.74, 1.0)
FLANGE_SPHERE_CM = 1.0  # a marker a few pixels wide at a metre's viewing distance


def hand_eye_messages(tables: dict[str, pa.Table], rec: Any) -> list[VizMessage]:
    """The messages (module docstring) from the committed stage tables (``session``,
    ``flange_poses``, ``detections``, ``camera_fit``, ``camera_residuals``) and the
    recording ``rec``."""
    from pipeline.sensor.camera import Intrinsics
    from pipeline.stages.camera_fit import fit_pixels
    from pipeline.stages.flange_poses import flange_matrices
    from pipeline.stages.hand_eye_fit import fitted_hand_eye

    rig = json.loads(tables["session"].column("rig_json")[0].as_py())
    fixed, tool, lens = fitted_hand_eye(tables["camera_fit"], Intrinsics.from_dict(rig["camera"]))
    images = fit_pixels(rig, tables["detections"])[0]
    flange = flange_matrices(tables["flange_poses"], images)
    fixed_name, moving = bodies(rig["setup"])

    def tf(parent: str, child: str, T: np.ndarray, t: int = 0) -> VizMessage:
        return VizMessage(TF_TOPIC, "foxglove.FrameTransform",
                          fg.frame_transform(parent, child, T, t), t)  # fmt: skip

    out = [tf(BASE, fixed_name, fixed), tf(FLANGE, moving, tool)]
    out += [tf(BASE, FLANGE, F, image_time(k)) for k, F in enumerate(flange)]
    seen = invert_transform(fixed) @ flange @ tool  # the moving body in the fixed one's frame
    depth = float(np.max(np.linalg.norm(seen[:, :3, 3], axis=1)))  # the farthest target
    out += image_messages(images, tables["camera_residuals"], rec)
    out.append(scene_message(lens.vector(), rig, depth, flange_entity(flange[:, :3, 3])))
    return in_time_order(out)


def flange_entity(points_cm: np.ndarray) -> fg.Json:
    """The recorded flange positions (frame ``base``): a sphere at each, joined in order."""
    return fg.scene_entity(
        BASE,
        "flange_poses",
        lines=[fg.line_strip(points_cm, FRUSTUM)],
        spheres=fg.spheres(points_cm, FLANGE_SPHERE_CM, FLANGE_COLOUR),
    )
