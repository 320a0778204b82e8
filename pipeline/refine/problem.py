"""A session's refinement problem from its stage tables: model, block, start, names.

The parameters, each declared once: per joint its axis line (``joint<k>.rx, ry[, tx, ty]``,
group ``axis``), per target point its position at q̄^s (``<point id>.x, y, z``, group
``point``; ids ``tool`` and ``sweep<j>/<target>``), then the measurement block's own
(sensor self-calibration; group from the name's head: ``mic``, ``bias``, ``speed``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.optim.block import Array, MeasurementBlock
from pipeline.refine.kinematics import ChainModel, model_for_keys, start_points
from pipeline.refine.points import PointBlock, point_block, with_reading_noise
from pipeline.refine.solve import Problem
from pipeline.stages.positions import positions
from pipeline.stages.recording import sweep_name
from pipeline.stages.session import session_robot, session_sensor
from pipeline.units import joints_to_internal

BLOCK_GROUPS = ("mic", "bias", "speed")


@dataclass(frozen=True)
class SessionProblem:
    """The problem, its start and the parameters' names, units (internal) and groups."""

    problem: Problem
    x0: Array
    point_ids: tuple[str, ...]
    names: tuple[str, ...]
    units: tuple[str, ...]
    groups: tuple[str, ...]


def parameter_labels(
    model: ChainModel, block: MeasurementBlock
) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
    """Names, units and groups of ``x = [θ_kin, x_block]`` (module docstring)."""
    names = list(model.param_names)
    groups = ["axis"] * model.n_axis_params + ["point"] * (3 * model.n_points)
    for name in block.param_names:
        head = name.split(".")[0].split("_")[0]
        groups.append(head if head in BLOCK_GROUPS else "sensor")
    names += list(block.param_names)
    units = (*model.param_units, *block.param_units)
    return tuple(names), tuple(units), tuple(groups)


def _check_coverage(block_keys: pa.Table, n: int, prismatic: np.ndarray, source: str) -> None:
    """Refuse a session whose joint sweep or tool measurement has too few usable positions
    for the model (a revolute axis needs 3 positions, a prismatic line 2, the tool 1)."""
    sweep = block_keys.column("sweep").to_numpy()
    for s in range(0, n + 1):
        need = 1 if s == 0 else (2 if prismatic[s - 1] else 3)
        have = int((sweep == s).sum())
        if have < need:
            what = "the tool measurement" if s == 0 else f"sweep {sweep_name(s)}"
            raise StageError(
                f"{source}: {what} has {have} usable positions",
                expected=f"at least {need} to refine the chain",
                got=f"{have} (the others null: no usable measurement)",
                fix="re-record that sweep, or --param refine.enabled=false",
            )


def reading_tangents(model: ChainModel, x: Array) -> Array:
    """``∂p/∂q_k`` (K, n, 3) of every key's position, by central differences of the model
    in its joint values (step 1e-6 rad / cm: the positions are smooth; only a weight)."""
    h = 1e-6
    out = np.zeros((model.theta.shape[0], model.theta.shape[1], 3))
    for k in range(model.theta.shape[1]):
        step = np.zeros_like(model.theta)
        step[:, k] = h
        up = replace(model, theta=model.theta + step).positions(x)
        down = replace(model, theta=model.theta - step).positions(x)
        out[:, k] = (up - down) / (2.0 * h)
    return out


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


def session_problem(
    inputs: Mapping[str, Any],
    loss: str = "soft_l1",
    f_scale: float = 3.0,
    level: str = "points",
    speed_knot_s: float = 120.0,
) -> SessionProblem:
    """The problem of a session at ``level`` (``inputs``: session, joints, positions, frames;
    level ``ranges``: and ranges). The start: the thesis frames and the target points they
    imply from the measured positions."""
    from pipeline.sensor.geometry import DigitizerGeometry

    session = inputs["session"]
    robot = session_robot(session)
    block: MeasurementBlock
    if level == "ranges":
        from pipeline.sensor.range_model import RangeModelOptions, range_block

        block = range_block(inputs["ranges"], session, RangeModelOptions(speed_knot_s))
        measured = measured_at(block.keys, inputs["positions"])
        usable = block.keys.filter(pa.array(np.isfinite(measured).all(axis=1)))
    else:
        geometry = None
        if session_sensor(session) == "sonic":
            rig = json.loads(session.column("rig_json")[0].as_py())
            geometry = DigitizerGeometry.from_dict(rig)
        block = points = point_block(inputs["positions"], geometry)
        measured, usable = points.measured, points.keys
    _check_coverage(usable, robot.n_joints, robot.prismatic, "positions")
    model = model_for_keys(block.keys, session, inputs["joints"], inputs["frames"])
    ids = model.point_names
    p0 = start_points(model, measured)
    if isinstance(block, PointBlock):
        x = np.concatenate([np.zeros(model.n_axis_params), p0.ravel()])
        res = joints_to_internal(robot.encoder_resolution, robot.prismatic)
        block = with_reading_noise(block, reading_tangents(model, x), res**2 / 12.0)
    x0 = np.concatenate([np.zeros(model.n_axis_params), p0.ravel(), block.x0])
    names, units, groups = parameter_labels(model, block)
    return SessionProblem(
        Problem(model, block, loss, f_scale), x0, tuple(ids), names, units, groups
    )


def internal_factors(refine: pa.Table) -> Array:
    """Per row of a ``refine`` table, the factor from its boundary unit to the internal
    one (deg -> rad; cm and ratios unchanged): values scale by it, covariances by its
    outer product."""
    unit = np.array(refine.column("unit").to_pylist())
    return np.where(unit == "deg", np.radians(1.0), 1.0)


def refined_x(refine: pa.Table) -> Array:
    """The fitted ``x`` (internal units) of a ``refine`` table."""
    return np.asarray(refine.column("value").to_numpy() * internal_factors(refine), float)
