"""The refinement's problem from a session's stage tables: the adapter between the tables
(``session``, ``joints``, ``positions``, ``frames``, ``ranges``) and the math of
:mod:`pipeline.refine` and :mod:`pipeline.sensor.range_model`, which take arrays and
dataclasses. Used by the stages ``refine`` and ``holdout``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.errors import ArmsigError
from pipeline.kinematics.nongeometric import NO_TERMS, Terms
from pipeline.optim.block import Array, MeasurementBlock
from pipeline.refine.kinematics import ChainModel, chain_model
from pipeline.refine.orientation import OrientationRows
from pipeline.refine.points import PointBlock, PositionRows, position_covariances
from pipeline.refine.problem import (
    SessionProblem,
    chain_problem,
    check_coverage,
    parameter_labels,
)
from pipeline.sensor.geometry import DigitizerGeometry
from pipeline.stages.frames import chain_from_frames, matrices_from_columns, readings_at
from pipeline.stages.joints import rows_of_keys
from pipeline.stages.positions import _COV_INDEX, COV_ENTRIES, positions
from pipeline.stages.session import session_geometry, session_plan, session_robot, session_sensor
from pipeline.sweeps import CHECK_SWEEP
from pipeline.units import joints_to_internal

if TYPE_CHECKING:  # the range model is imported when a session is refined at its ranges
    from pipeline.sensor.range_model import RangeBlock, RangeModelOptions


def _column(table: pa.Table, name: str) -> np.ndarray:
    return table.column(name).to_numpy(zero_copy_only=False).astype(float)


def position_rows(table: pa.Table) -> PositionRows:
    """The positions of a ``positions`` table and their recorded noise (null -> NaN)."""
    m = table.num_rows
    cov = np.full((m, 3, 3), np.nan)
    entries = [_column(table, f"cov_{e}_cm2") for e in COV_ENTRIES]
    full = np.isfinite(np.stack(entries, axis=1)).all(axis=1)
    for v, (i, j) in zip(entries, _COV_INDEX, strict=True):
        cov[full, i, j] = cov[full, j, i] = v[full]
    return PositionRows(
        p=positions(table),
        cov=cov,
        sigma_cm=_column(table, "sigma_cm"),
        scatter_cm=_column(table, "scatter_cm"),
        n_used=table.column("n_used").to_numpy().astype(float),
        n_samples=table.column("n_samples").to_numpy(),
    )


def table_covariances(table: pa.Table, geometry: DigitizerGeometry | None = None) -> Array:
    """Σ (m, 3, 3) of the rows of a ``positions`` table, as the refinement weighs them
    (:func:`pipeline.refine.points.position_covariances`)."""
    return position_covariances(position_rows(table), geometry)


def point_block(table: pa.Table, geometry: DigitizerGeometry | None = None) -> PointBlock:
    """The block of every usable fit position of a ``positions`` table: finite, and not
    of the check sweep (held out) (:mod:`pipeline.refine.points`)."""
    p = positions(table)
    sweep = table.column("sweep").to_numpy()
    use = np.isfinite(p).all(axis=1) & (sweep != CHECK_SWEEP)
    rows = table.filter(pa.array(use))
    L = np.linalg.cholesky(table_covariances(rows, geometry))
    return PointBlock(
        keys=rows.select(["sweep", "step", "target"]),
        measured=p[use],
        whiten=np.linalg.inv(L),
    )


def session_range_block(
    ranges: pa.Table, session: pa.Table, options: RangeModelOptions | None = None
) -> RangeBlock:
    """The range-level block of a sonic session (:func:`pipeline.sensor.range_model.
    range_block`) from its ``ranges`` and ``session`` tables; a point-sensor session is
    refused with one line."""
    from pipeline.sensor.range_model import range_block

    geometry = session_geometry(session)
    if geometry is None:
        raise ArmsigError(
            "the range model needs a sonic session",
            expected="sensor 'sonic' in /rig/description",
            got=repr(session_sensor(session)),
            fix="use the point-sensor block for this session",
        )
    return range_block(ranges, geometry, session_plan(session)["order"], options)


def rows_at(keys: pa.Table, table: pa.Table) -> npt.NDArray[np.int64]:
    """Row of ``table`` at each (sweep, step, target) of ``keys``, joined by key; −1 where
    the table has none."""
    cols = ("sweep", "step", "target")
    at = {
        k: i for i, k in enumerate(zip(*(table.column(c).to_pylist() for c in cols), strict=True))
    }
    rows = [at.get(k, -1) for k in zip(*(keys.column(c).to_pylist() for c in cols), strict=True)]
    return np.array(rows, np.int64)


def measured_at(keys: pa.Table, table: pa.Table) -> Array:
    """Positions (K, 3) of a ``positions`` table at ``keys`` (sweep, step, target), joined
    by key; NaN where the table has none."""
    p = np.vstack([positions(table), np.full((1, 3), np.nan)])
    return p[rows_at(keys, table)]


def model_for_keys(
    keys: pa.Table,
    session: pa.Table,
    joints: pa.Table,
    frames: pa.Table,
    tool_rotation: bool = False,
    terms: Terms = NO_TERMS,
) -> ChainModel:
    """The chain model of the observations ``keys`` (columns sweep, step, target), started
    at the thesis ``frames`` table, with each key's readings joined from ``joints`` by
    (sweep, step) (:func:`pipeline.refine.kinematics.chain_model`); ``tool_rotation``: the
    tool's orientation is a parameter; ``terms``: the non-geometric terms, their regressor
    on the design chain at the readings (:mod:`pipeline.kinematics.nongeometric`)."""
    robot = session_robot(session)
    n, pris = robot.n_joints, robot.prismatic
    plan = session_plan(session)
    tool = plan.get("tool_target")
    shared = plan.get("sweeps_measure_tool", False) and tool is not None
    on_tool = [str(t) for t in plan.get("tool_targets", [tool])] if shared else []
    q_sig = chain_from_frames(frames, pris).joint_offsets
    sweep = keys.column("sweep").to_numpy().astype(np.int64)
    step = keys.column("step").to_numpy().astype(np.int64)
    theta = np.zeros((len(sweep), n))
    for s in np.unique(sweep):
        sel = np.flatnonzero(sweep == s)
        q = readings_at(joints, int(s), step[sel], n, pris)
        theta[sel] = joints_to_internal(q, pris) - q_sig
    target = keys.column("target").to_pylist()
    F = matrices_from_columns(frames)[:n]
    model = chain_model(sweep, target, theta, F, pris, tool, on_tool, tool_rotation)
    if not terms:
        return model
    payload = np.nan_to_num(payloads_at(joints, sweep, step), nan=0.0)
    return replace(
        model, terms=terms, design=robot.design_chain(), reading_zero=q_sig, payload_kg=payload
    )


def measured_payloads(joints: pa.Table) -> tuple[float, ...]:
    """The distinct payloads (kg, ascending) recorded with the configurations the fit uses
    (every sweep but ``check``); empty when none was recorded."""
    fit = joints.column("sweep").to_numpy() != CHECK_SWEEP  # the column, not the table
    kg = joints.column("payload_kg").to_numpy(zero_copy_only=False).astype(float)[fit]
    return tuple(float(v) for v in np.unique(kg[np.isfinite(kg)]))


def payloads_at(joints: pa.Table, sweep: np.ndarray, step: np.ndarray) -> Array:
    """The payload (kg) recorded with each configuration (sweep, step), joined by key from
    the ``joints`` table; NaN where none was recorded."""
    first = joints.select(["sweep", "step", "payload_kg"]).filter(
        pa.array(joints.column("joint").to_numpy() == 1)
    )
    kg = first.column("payload_kg").to_numpy(zero_copy_only=False).astype(float)
    i, found = rows_of_keys(first, sweep, step)
    return np.where(found, kg[i] if len(kg) else np.nan, np.nan)


def independent_terms(terms: Terms, model: ChainModel, reach_cm: float) -> Terms:
    """The ``terms`` that are parameters of ``model`` (built with ``terms``): per joint,
    those whose regressor columns over the observations' readings are independent. A
    term that is zero at every reading (a joint whose axis is along gravity feels no
    gravity torque, a mass on a joint's own axis none about it) or a combination of the
    others (two lumped masses at one point, a Puma's wrist centre; a link's own mass
    about its joint against that joint's first harmonic) is a property of the design,
    not of the data: it is no parameter. Pivoted QR (LAPACK ``geqp3``) of each joint's
    unit-normed columns, a pivot below 1e-9 of the first dropping its column; zero: every
    value at most 1e-9 rad, or 1e-9 of the reach ``reach_cm`` (cm) for a lever."""
    from scipy.linalg import qr

    scale = np.array([reach_cm if u == "rad/cm" else 1.0 for u in terms.units])
    keep = np.zeros(terms.size, bool)
    for j, (top, R) in enumerate(_regressor_factors(model)):
        cols = np.flatnonzero(top * scale > 1e-9)
        if not len(cols):
            continue
        if R is None:  # the columns themselves (one chunk): as before issue 45
            block = model.regressor[:, j, cols]
            block = block / np.linalg.norm(block, axis=0)
        else:  # R of the columns (the same QR): unit-normed (norms kept by Q)
            block = np.asarray(np.linalg.qr(R[:, cols], mode="r"))
            block = block / np.linalg.norm(block, axis=0)
        _, R, piv = qr(block, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        keep[cols[piv[: len(d)][d > 1e-9 * d[0]]]] = True
    names = [nm for nm, k in zip(terms.names, keep, strict=True) if k]
    return Terms.from_names(names)


def _regressor_factors(model: ChainModel) -> list[tuple[Array, Array | None]]:
    """Per joint, the largest magnitude of each regressor column over the observations,
    and, past :data:`pipeline.refine.solve.CHUNK` observations, the columns' ``R``
    (TSQR over chunks of observations: the regressor is never formed whole; else None)."""
    from pipeline.refine.solve import chunks, r_with_rows

    parts = chunks(model, keep=False)
    if len(parts) == 1:
        top = np.abs(model.regressor).max(axis=0)  # (n, size)
        return [(top[j], None) for j in range(model.n_joints)]
    n, size = model.n_joints, model.terms.size
    tops, Rs = np.zeros((n, size)), [np.zeros((0, size)) for _ in range(n)]
    for _, sub in parts:
        Phi = sub.regressor
        tops = np.maximum(tops, np.abs(Phi).max(axis=0))
        Rs = [r_with_rows(Rs[j], Phi[:, j, :]) for j in range(n)]
    return list(zip(tops, Rs, strict=True))


def orientation_rows(
    keys: pa.Table, table: pa.Table, plan: Mapping[str, Any]
) -> OrientationRows | None:
    """The measured tool orientations of a pose set: rows of the ``positions`` table of the
    pose set's tool target with an orientation and its σ, each paired by (sweep, step,
    target) with its position among ``keys``; None when there is none."""
    import pyarrow.compute as pc

    from pipeline.stages.frames import pose_tool_target
    from pipeline.sweeps import POSES_SWEEP

    tool = pose_tool_target(plan, table)
    rows = table.filter(
        pc.and_(
            pc.equal(table.column("sweep"), POSES_SWEEP), pc.equal(table.column("target"), tool)
        )
    )
    wxyz = np.stack([_column(rows, f"orientation_{c}") for c in "wxyz"], axis=1)
    sigma = _column(rows, "orientation_sigma_deg")
    at = rows_at(rows.select(["sweep", "step", "target"]), keys.select(["sweep", "step", "target"]))
    ok = np.isfinite(wxyz).all(axis=1) & np.isfinite(sigma) & (at >= 0)
    if not ok.any():
        return None
    from scipy.spatial.transform import Rotation

    R = Rotation.from_quat(wxyz[ok], scalar_first=True).as_matrix()
    return OrientationRows(index=at[ok], measured=R, sigma_rad=np.radians(sigma[ok]))


def session_problem(
    inputs: Mapping[str, Any],
    loss: str = "soft_l1",
    f_scale: float = 3.0,
    level: str = "points",
    speed_knot_s: float = 0.0,
    terms: Terms = NO_TERMS,
) -> SessionProblem:
    """The problem of a session at ``level`` (``inputs``: session, joints, positions, frames;
    level ``ranges``: and ranges, its speed spline's knots ``speed_knot_s`` apart, 0:
    chosen from the rods) (:func:`pipeline.refine.problem.chain_problem`), with the
    non-geometric ``terms`` of them that are parameters (:func:`independent_terms`)."""
    session = inputs["session"]
    robot = session_robot(session)
    block: MeasurementBlock
    orientation: OrientationRows | None = None
    if level == "ranges":
        from pipeline.sensor.range_model import RangeModelOptions

        block = session_range_block(
            inputs["ranges"], session, RangeModelOptions(speed_knot_s or None)
        )
        measured = measured_at(block.keys, inputs["positions"])
        usable = block.keys.filter(pa.array(np.isfinite(measured).all(axis=1)))
    else:
        block = points = point_block(inputs["positions"], session_geometry(session))
        measured, usable = points.measured, points.keys
        orientation = orientation_rows(points.keys, inputs["positions"], session_plan(session))
    sweep = usable.column("sweep").to_numpy()
    if "poses" not in session_plan(session):  # a pose set: its identifiability decides
        check_coverage(sweep, robot.n_joints, robot.prismatic, "positions")
    rotation = orientation is not None
    model = model_for_keys(block.keys, session, inputs["joints"], inputs["frames"], rotation)
    res = joints_to_internal(robot.encoder_resolution, robot.prismatic)
    rigid = chain_problem(model, block, measured, loss, f_scale, res**2 / 12.0, orientation)
    return with_terms(rigid, terms, inputs) if terms else rigid


def with_terms(sp: SessionProblem, terms: Terms, inputs: Mapping[str, Any]) -> SessionProblem:
    """The rigid problem ``sp`` with the non-geometric ``terms`` that are parameters
    (:func:`independent_terms`), their coefficients after the chain's, started at zero:
    the same block, whose encoder-reading noise is weighed at the start, where the terms
    are zero (what :func:`session_problem` with ``terms`` returns)."""
    robot = session_robot(inputs["session"])
    rigid = sp.problem.model
    keys = sp.problem.block.keys
    args = (keys, inputs["session"], inputs["joints"], inputs["frames"], rigid.tool_rotation)
    model = model_for_keys(*args, terms)
    independent = independent_terms(terms, model, robot.reach_cm)
    if independent != terms:
        model = model_for_keys(*args, independent)
    n = rigid.n_params
    x0 = np.concatenate([sp.x0[:n], np.zeros(model.terms.size), sp.x0[n:]])
    names, units, groups = parameter_labels(model, sp.problem.block)
    problem = replace(sp.problem, model=model)
    return SessionProblem(problem, x0, model.point_names, names, units, groups)
