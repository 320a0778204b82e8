"""Stage ``uncertainty``: the refined signature's predicted tool error over the workspace.

The refinement's covariance of the chain parameters (its rows of groups ``axis``, the
``tool`` point and the non-geometric terms, the marginal of the kinematic part) propagated
to the tool, through the terms the signature applies (issue 27), at
``configurations`` random configurations within the joint limits (seeded, drawn as the
audit draws them), raw and after what the audit's base and tool re-alignment absorbs
(:mod:`pipeline.refine.uncertainty`, the formulas there). Zero rows when the refinement
is disabled (no covariance). Summaries (RMS, 95 %, max) come from the rows:
:func:`summary`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.kinematics.nongeometric import KINDS
from pipeline.stages.base import Stage, check_param
from pipeline.stages.session import session_robot

#: Most configurations: (m, 6, P) error maps of ~30 parameters stay near 100 MB at 1e5.
MAX_CONFIGURATIONS = 100_000
#: Names of the tool point's rows of the ``refine`` table (``tool.x`` or ``tool_x_cm``).
_TOOL_ROW = re.compile(r"^tool[._]")


@dataclass(frozen=True)
class Params:
    """``configurations``: random configurations within the limits (the audit's 1000);
    ``seed``: their seed (the audit's 0, so both see the same configurations)."""

    configurations: int = 1000
    seed: int = 0

    def __post_init__(self) -> None:
        ok = 1 <= self.configurations <= MAX_CONFIGURATIONS
        check_param(self, "uncertainty", "configurations", ok, f"1 to {MAX_CONFIGURATIONS}")


def kinematic_covariance(refine: pa.Table, n_axis: int) -> tuple[np.ndarray, np.ndarray]:
    """``x`` and ``Σ`` (internal units: rad, cm) of the axis parameters, the tool point (and
    rotation) and the non-geometric terms, in the order of :class:`ChainModel`'s
    parameters, rows picked from the ``refine`` table by group and name (joined by key,
    not position)."""
    group = refine.column("group").to_pylist()
    name = refine.column("name").to_pylist()
    axis = [i for i, g in enumerate(group) if g == "axis"]
    tool = [i for i, (g, s) in enumerate(zip(group, name, strict=True))
            if g == "point" and _TOOL_ROW.match(s)]  # fmt: skip
    tool += [i for i, g in enumerate(group) if g == "tool_rotation"]  # a 6-D tool (issue 26)
    terms = [i for i, g in enumerate(group) if g in KINDS]
    if len(axis) != n_axis or len(tool) not in (3, 6):
        raise StageError(
            "uncertainty: the refine table does not match the session's chain",
            expected=f"{n_axis} rows of group 'axis', 3 of the tool point (and 3 of its rotation)",
            got=f"{len(axis)} axis rows, {len(tool)} tool rows",
            fix="`pipeline identify SESSION --force` recomputes the refinement",
        )
    idx = np.array(axis + tool + terms)
    from pipeline.stages.refine import internal_factors, refined_x

    scale = internal_factors(refine)
    x = refined_x(refine)
    C = np.array(refine.column("covariance").to_pylist(), float) * np.outer(scale, scale)
    return x[idx], C[np.ix_(idx, idx)]


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.kinematics.nongeometric import NO_TERMS
    from pipeline.refine.kinematics import TOOL_POINT, ChainModel
    from pipeline.refine.uncertainty import predict_model, tool_poses
    from pipeline.stages.frames import chain_from_frames, matrices_from_columns
    from pipeline.stages.refine import nongeometric_model

    refine = inputs["refine"]
    if refine.num_rows == 0:  # refinement disabled: no covariance
        return _table(np.zeros((0, 3)), None, 0.0)
    robot = session_robot(inputs["session"])
    n, pris = robot.n_joints, robot.prismatic
    frames = inputs["frames"]
    q = robot.random_configurations(params.configurations, params.seed)
    m = len(q)
    q_sig = chain_from_frames(frames, pris).joint_offsets
    ng = nongeometric_model(refine, robot)
    model = ChainModel(
        frames0=matrices_from_columns(frames)[:n],
        prismatic=pris,
        link=np.full(m, n, np.int64),
        theta=q - q_sig,
        point=np.zeros(m, np.int64),
        point_names=(TOOL_POINT,),
        tool_rotation="tool_rotation" in refine.column("group").to_pylist(),
        terms=NO_TERMS if ng is None else ng.terms,
        design=None if ng is None else ng.design,
        reading_zero=q_sig,
        payload_kg=np.full(m, 0.0 if ng is None else ng.payload_kg),
    )
    x, Sigma = kinematic_covariance(refine, model.n_axis_params)
    pred = predict_model(model, x, Sigma, params.seed)
    return _table(tool_poses(model, x)[0], pred, pred.max95_cm)


def _table(p: np.ndarray, pred: Any, max95: float) -> pa.Table:
    m = len(p)
    cols = ("position_cm", "position_aligned_cm", "orientation_deg", "orientation_aligned_deg")
    return pa.table(
        {
            "configuration": pa.array(np.arange(m), pa.int32()),
            **{f"{a}_cm": pa.array(p[:, k], pa.float64()) for k, a in enumerate("xyz")},
            **{
                f"sigma_{c}": pa.array(np.zeros(0) if pred is None else getattr(pred, c))
                for c in cols
            },
            "max95_cm": pa.array(np.full(m, max95), pa.float64()),
        }
    )


def summary(table: pa.Table) -> dict[str, float] | None:
    """RMS, 95th percentile and max of each σ column, and ``max95_cm``; None without rows."""
    if table.num_rows == 0:
        return None
    out = {"max95_cm": float(table.column("max95_cm")[0].as_py())}
    for c in table.column_names:
        if c.startswith("sigma_"):
            v = table.column(c).to_numpy()
            unit = c.rsplit("_", 1)[1]
            stem = c.removesuffix("_" + unit)
            out[f"{stem}_rms_{unit}"] = float(np.sqrt(np.mean(v**2)))
            out[f"{stem}_p95_{unit}"] = float(np.percentile(v, 95))
            out[f"{stem}_max_{unit}"] = float(v.max())
    return out


STAGE = Stage(
    "uncertainty",
    2,  # 2: the non-geometric terms' covariance and deflection in the prediction (issue 27)
    ("session", "refine", "frames"),
    Params(),
    compute,
    "predicted tool error of the refined signature over random configurations",
)
