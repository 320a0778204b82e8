"""The stage lists of the runner (:mod:`pipeline.stages.runner`): which stage modules
identify a session of each sensor, which evaluate it, the session files other than stage
outputs that stages read, and the product the identification stages commit.

A new sensor's stage list goes here (:data:`SENSOR_STAGE_MODULES`, docs/architecture.md).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from pipeline.stages.base import Stage

#: Identification stage modules of a sonic session in pipeline order (each defines
#: ``STAGE``): ranges -> compensate -> triangulate -> the sensor-neutral ``positions``.
STAGE_MODULES = (
    "session",
    "ranges",
    "joints",
    "compensate",
    "triangulate",
    "positions",
    "features",
    "residuals",
    "frames",
    "refine",
    "chain",
    "smodel",
    "dh",
    "uncertainty",
    "holdout",
    "verdict",
)
#: Identification stage modules of a point-sensor session: module ``points`` is the one
#: stage that turns ``/points`` into the ``positions`` table (its stage name).
POINT_STAGE_MODULES = (
    "session",
    "joints",
    "points",
    "features",
    "residuals",
    "frames",
    "refine_points",
    "chain",
    "smodel",
    "dh",
    "validation",
    "uncertainty",
    "holdout_points",
    "verdict",
)
#: Identification stage modules of a camera session (issue 39): the fit to the pixels,
#: then its ``frames`` (the start), ``chain``, ``uncertainty``, held-out images and
#: ``verdict`` (modules ``camera_*`` with the pose sets' stage names where the table is
#: theirs).
CAMERA_STAGE_MODULES = (
    "session",
    "joints",
    "image_detections",  # stage ``detections``: the recorded ones, or detected in its images
    "camera_fit",
    "camera_residuals",
    "camera_frames",
    "camera_chain",
    "camera_uncertainty",
    "camera_holdout",
    "camera_verdict",
)
#: recorded sensor kind (``/rig/description`` sensor) -> its identification stage modules
SENSOR_STAGE_MODULES = {"sonic": STAGE_MODULES, "points": POINT_STAGE_MODULES,
                        "camera": CAMERA_STAGE_MODULES,
                        # flange poses, no joints (issue 40): the camera only, no product
                        "camera-flange": ("session", "flange_poses", "image_detections",
                                          "hand_eye_fit", "hand_eye_residuals",
                                          "hand_eye_holdout")}  # fmt: skip
#: The last identification stage: a stage list holding it (and ``session``) has a product.
LAST_STAGE = "verdict"
#: Stage modules of ``pipeline evaluate`` (run after the identification, same runner).
EVALUATE_STAGE_MODULES = (
    "evaluate_teach",
    "evaluate_program",
    "evaluate_measurements",
    "evaluate_indices",
)
#: Stage inputs that are files of the session folder other than stage outputs:
#: name -> (file name, ``module:function`` that loads it from its path).
#: They are hashed by content, like the recording.
FILE_INPUTS = {
    "signature": ("signature.json", "pipeline.signature.session:load_session_signature"),
    "evaluation": ("evaluation.mcap", "pipeline.contract.evaluation:read_evaluation"),
}
#: The product of the identification stages, written by the run that commits them:
#: its name (a :data:`FILE_INPUTS` key) and ``module:function`` of its writer
#: ``(session_dir, hashes, force) -> (path, doc, written)`` and of its check
#: ``(session_dir, hashes) -> (state, reason)``; ``hashes``: the stages' content hashes.
PRODUCT = (
    "signature",
    "pipeline.signature.session:write_signature",
    "pipeline.signature.session:signature_status",
)


def stages(modules: tuple[str, ...] = STAGE_MODULES) -> list[Stage]:
    """All stages of a stage list (default: a sonic session's identification), in order."""
    return [importlib.import_module(f"pipeline.stages.{m}").STAGE for m in modules]


def identification_names(sensor: str) -> tuple[str, ...]:
    """The names (output files ``stages/<name>.arrow``) of the identification stages of a
    session of sensor kind ``sensor`` (``sonic`` or ``points``)."""
    return tuple(s.name for s in stages(SENSOR_STAGE_MODULES[sensor]))


def is_identification(names: list[str] | set[str]) -> bool:
    """Whether a stage list is an identification (it has a product)."""
    return LAST_STAGE in names and "session" in names


def function_of(ref: str) -> Callable[..., Any]:
    """The function named by ``module:function``."""
    module, func = ref.split(":")
    return getattr(importlib.import_module(module), func)  # type: ignore[no-any-return]
