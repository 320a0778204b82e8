"""Stage ``frames`` of a camera session: the chain the camera fit started from (issue 39).

The design chain placed by the closed-form hand-eye (``camera_fit``'s ``start`` rows and
its start frames: :func:`pipeline.refine.camera_fit.camera_model`), as the frames
``S̄_0 … S̄_n`` and the tool (the body on the flange) in the sensor frame, at ``q̄^s``
(frames schema). It is the signature file's ``thesis_smodel`` of a camera session: the
model before the fit, beside the fitted one (stage ``chain``, :mod:`camera_chain`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import NoParams, Stage
from pipeline.stages.session import session_robot


def kinematic_x(table: pa.Table, column: str) -> np.ndarray:
    """The chain's parameters (axis lines, tool point, tool rotation; rad, cm) of a
    ``camera_fit`` table's ``column`` (``start`` or ``value``), in the model's order."""
    rows = table.to_pylist()
    kin = [r for r in rows if r["group"] in ("axis", "point", "tool_rotation")]
    return np.array([np.radians(r[column]) if r["unit"] == "deg" else r[column] for r in kin])


def frames_of(inputs: Mapping[str, Any], column: str) -> pa.Table:
    """The frames table of the chain at a ``camera_fit`` column (``start`` or ``value``)."""
    from pipeline.stages.camera_fit import fitted_model
    from pipeline.stages.frames import frames_table
    from pipeline.units import joints_to_boundary

    robot = session_robot(inputs["session"])
    table = inputs["camera_fit"]
    model, _, _, q_sig = fitted_model(table, robot)
    T = model.signature_frames(kinematic_x(table, column), 0)
    return frames_table(T, joints_to_boundary(q_sig, robot.prismatic), robot.prismatic)


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    return frames_of(inputs, "start")


STAGE = Stage(
    "frames",
    1,
    ("session", "camera_fit"),
    NoParams(),
    compute,
    "the camera fit's start: the design chain placed by the closed-form hand-eye (camera)",
)
