"""Stage ``chain``: the signature chain every later stage and signature.json read.

The refined frames S̄_0 … S̄_n and the tool (frames schema, schemas/arrow/frames.json)
from stage ``refine``'s axis lines and tool point, in the gauge of docs/refine.md: each
refined S̄_{k−1} is the thesis frame moved least (origin: the thesis origin's foot on the
refined axis; X: the thesis X made normal to it), S̄_n = S̄_{n−1}, the tool the refined
tool point in S̄_n with S̄_n's orientation. With the refinement disabled (zero rows) the
thesis's ``frames`` table unchanged: every later table is then the thesis's, byte for byte.
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
    from pipeline.refine.kinematics import ChainModel, refined_frames_table
    from pipeline.refine.problem import refined_x

    robot = session_robot(inputs["session"])
    n = robot.n_joints
    groups = np.array(refine.column("group").to_pylist())
    names = refine.column("name").to_pylist()
    points = [nm for nm, g in zip(names, groups, strict=True) if g == "point"]
    if not points or points[0] != "tool.x":
        raise StageError(
            "refine: no tool point as the first point parameter",
            expected="rows tool.x, tool.y, tool.z first among group 'point'",
            got=points[0] if points else "no point rows",
            fix="rerun with --from refine",
        )
    empty = np.zeros(0, np.int64)
    from pipeline.stages.frames import matrices_from_columns

    model = ChainModel(
        frames0=matrices_from_columns(frames)[:n],
        prismatic=robot.prismatic,
        link=empty,
        theta=np.zeros((0, n)),
        point=empty,
        n_points=len(points) // 3,
    )
    x = refined_x(refine)[: model.n_params]
    return refined_frames_table(model, x, frames)


STAGE = Stage(
    "chain",
    1,
    ("session", "refine", "frames", "joints"),
    NoParams(),
    compute,
    "the signature chain: refined frames (or the thesis's when refine is disabled)",
)
