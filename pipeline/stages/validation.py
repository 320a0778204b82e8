"""Stage ``validation``: the signature's position error on measured tool-target points.

For every measured position of the tool target (``plan.tool_target``) the model's
prediction is the S-Model chain's forward kinematics with its tool at the recorded
joint values under the recorded payload
(:func:`pipeline.evaluation.validation.model_points`). Rows of sweep ``check`` are
validation configurations the identification never used (role ``check``); the tool
measurement, and the joint sweeps' rows of the tool target when they measured the tool
point itself (``plan.sweeps_measure_tool``, SScanSS-2 style: every row measures the end
effector), are fit data (role ``fit``). Each role's
distances are also given after registering the base: the least-squares rigid motion
of that role's predicted points onto its measured ones.

Beside them, the design model's error (the "before" of a before/after, issue 29): the
design chain with its base and tool point registered to the *fit* points
(:func:`pipeline.refine.baseline.register_design`), at every row: on the fit rows what the
uncalibrated arm does in a cell registered on them, on the check rows the same on points
neither fit saw.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.evaluation.validation import error_distances, model_points
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.frames import chain_from_frames, readings_at
from pipeline.stages.joints import sources_at
from pipeline.stages.positions import positions, sweep_rows
from pipeline.stages.recording import CHECK_SWEEP
from pipeline.stages.refine import nongeometric_model
from pipeline.stages.refine_problem import payloads_at
from pipeline.stages.session import session_plan, session_robot

ROLES = ("check", "fit")


def tool_target(plan: dict[str, Any], positions: pa.Table) -> str:
    """``plan.tool_target``, else the only target of the tool measurement."""
    if plan.get("tool_target"):
        return str(plan["tool_target"])
    tool = sweep_rows(positions, 0)
    ids = sorted(set(tool.column("target").to_pylist()))
    return ids[0] if len(ids) == 1 else ""


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    robot = session_robot(inputs["session"])
    plan = session_plan(inputs["session"])
    n, pris = robot.n_joints, robot.prismatic
    chain = chain_from_frames(inputs["chain"], pris)
    nongeometric = nongeometric_model(inputs["refine"], robot)
    pos = inputs["positions"]
    import pyarrow.compute as pc  # lazy: ~70 ms of import, which a warm run never needs

    from pipeline.refine.solve import CHUNK

    pos = pos.filter(pc.equal(pos.column("target"), tool_target(plan, pos)))
    xyz = positions(pos)
    sweep = pos.column("sweep").to_numpy().astype(np.int64)
    step = pos.column("step").to_numpy().astype(np.int64)
    ok = np.isfinite(xyz).all(axis=1)
    if not plan.get("sweeps_measure_tool", False):
        ok &= sweep <= 0  # sweep targets sit on the links: not the tool point
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("sweep", "step", "role")}
    arrays: dict[str, list[np.ndarray]] = {k: [] for k in ("p", "m", "raw", "reg", "q")}
    for role in ROLES:
        sel = ok & ((sweep == CHECK_SWEEP) == (role == "check"))
        if not sel.any():
            continue
        q = np.zeros((int(sel.sum()), n))
        for s in np.unique(sweep[sel]):
            at = sweep[sel] == s
            q[at] = readings_at(inputs["joints"], int(s), step[sel][at], n, pris)
        arrays["q"].append(q)
        kg = payloads_at(inputs["joints"], sweep[sel], step[sel])
        model = np.zeros((len(q), 3))
        for c in range(0, len(q), CHUNK):  # a chunk at a time: (k, n, 4, 4) stacks
            at = slice(c, c + CHUNK)
            model[at] = model_points(chain, q[at], pris, nongeometric, kg[at])
        raw, reg = error_distances(model, xyz[sel])
        cols["sweep"].append(sweep[sel])  # columns, not Python lists (issue 45)
        cols["step"].append(step[sel])
        cols["role"].append(np.full(int(sel.sum()), role))
        arrays["p"].append(xyz[sel])
        arrays["m"].append(model)
        arrays["raw"].append(raw)
        arrays["reg"].append(np.full(len(raw), np.nan) if reg is None else reg)
    p, m = (np.vstack(arrays[k]) if arrays[k] else np.zeros((0, 3)) for k in ("p", "m"))
    raw, reg = (np.concatenate(arrays[k]) if arrays[k] else np.zeros(0) for k in ("raw", "reg"))
    q_all = np.vstack(arrays["q"]) if arrays["q"] else np.zeros((0, n))
    sweeps, steps, roles = (
        np.concatenate(cols[k]) if cols[k] else np.zeros(0, t)
        for k, t in (("sweep", np.int64), ("step", np.int64), ("role", str))
    )
    fit = roles == "fit"
    design = _design_errors(robot, plan, q_all, p, fit)
    return pa.table(
        {
            "sweep": pa.array(sweeps, pa.int32()),
            "step": pa.array(steps, pa.int32()),
            "role": pa.array(roles, pa.string()),
            **{f"{a}_cm": pa.array(p[:, k], pa.float64()) for k, a in enumerate("xyz")},
            **{f"model_{a}_cm": pa.array(m[:, k], pa.float64()) for k, a in enumerate("xyz")},
            "error_cm": pa.array(raw, pa.float64()),
            "registered_error_cm": pa.array(reg, pa.float64(), mask=np.isnan(reg)),
            "design_error_cm": pa.array(design, pa.float64(), mask=np.isnan(design)),
            **sources_at(inputs["joints"], sweeps, steps),
        }
    )


def _design_errors(
    robot: Any, plan: dict[str, Any], q: np.ndarray, measured: np.ndarray, fit: np.ndarray
) -> np.ndarray:
    """Each row's distance (cm) from the design model with its base and tool point
    registered to the ``fit`` rows (module docstring); NaN where they cannot fix it (fewer
    than 3 fit points, or on one line)."""
    from pipeline.errors import StageError
    from pipeline.refine.baseline import register_design
    from pipeline.units import joints_to_internal

    out = np.full(len(q), np.nan)
    if fit.sum() < 3:
        return out
    qi = joints_to_internal(q, robot.prismatic)
    tool = np.asarray(plan.get("tool_local_cm", (0.0, 0.0, 0.0)), float)
    try:
        base = register_design(robot.design_chain(), qi[fit], measured[fit], tool)
    except StageError:  # the fit points do not fix a rigid motion
        return out
    out[:] = base.errors(qi, measured)
    return out


STAGE = Stage(
    "validation",
    6,  # 2: from the signature chain (stage chain); 3: with its non-geometric terms;
    # 4: design_error_cm, the registered design model beside it (issue 29);
    # 5: each row under its recorded payload (issue 44: the check rows' payload ignored);
    # 6: source_file and source_line of an imported row (issue 42)
    ("positions", "joints", "chain", "session", "refine"),
    NoParams(),
    compute,
    "model position error on validation (check) and fit points",
)
