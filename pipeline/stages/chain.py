"""Stage ``chain``: the signature chain every later stage and signature.json read.

The refined frames S̄_0 … S̄_n and the tool (frames schema, schemas/arrow/frames.json)
from stage ``refine``'s axis lines and tool point, in the gauge of docs/refine.md and
:mod:`pipeline.refine.kinematics`: each refined S̄_{k−1} is the thesis frame moved onto
the refined axis (origin where the refined axis meets the thesis frame's X-Y plane, X the
thesis X made normal to the refined axis), S̄_n = S̄_{n−1}, the tool the refined tool
point in S̄_n with S̄_n's orientation (:meth:`ChainModel.signature_frames`). With the
refinement disabled (zero rows) the thesis's ``frames`` table unchanged: every later
table is then the thesis's, byte for byte.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.session import session_robot


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    frames, refine = inputs["frames"], inputs["refine"]
    if refine.num_rows == 0:
        return frames
    from pipeline.refine.kinematics import TOOL_POINT, ChainModel
    from pipeline.stages.frames import matrices_from_columns, matrices_to_columns
    from pipeline.stages.refine import refined_x

    robot = session_robot(inputs["session"])
    n = robot.n_joints
    groups = np.array(refine.column("group").to_pylist())
    names = np.array(refine.column("name").to_pylist())
    points = [str(nm)[: -len(".x")] for nm in names[groups == "point"][::3]]
    if TOOL_POINT not in points:
        raise StageError(
            "refine: no tool point among the fitted parameters",
            expected="rows tool.x, tool.y, tool.z of group 'point'",
            got=", ".join(points) or "no point rows",
            fix="rerun with --from refine",
        )
    empty = np.zeros(0, np.int64)
    model = ChainModel(
        frames0=matrices_from_columns(frames)[:n],
        prismatic=robot.prismatic,
        link=empty,
        theta=np.zeros((0, n)),
        point=empty,
        point_names=tuple(points),
        tool_rotation="tool_rotation" in groups,
    )
    x = refined_x(refine)[: model.n_params]
    T = model.signature_frames(x, points.index(TOOL_POINT))
    out = frames  # the same rows, keys and q̄^s; the twelve matrix columns refined
    for name, values in matrices_to_columns(T).items():
        out = out.set_column(out.schema.get_field_index(name), name, pa.array(values))
    return out


STAGE = Stage(
    "chain",
    1,
    ("session", "refine", "frames", "joints"),
    NoParams(),
    compute,
    "the signature chain: refined frames (or the thesis's when refine is disabled)",
)
