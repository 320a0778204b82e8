"""A session's refinement problem: model, block, start, names (its stage tables are read
by :mod:`pipeline.stages.refine_problem`).

The parameters, each declared once: per joint its axis line (``joint<k>.rx, ry[, tx, ty]``,
group ``axis``), per target point its position at q̄^s (``<point id>.x, y, z``, group
``point``; ids ``tool`` and ``sweep<j>/<target>``), then the measurement block's own
(sensor self-calibration; group from the name's head: ``mic``, ``bias``, ``speed``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from pipeline.errors import StageError
from pipeline.optim.block import Array, MeasurementBlock
from pipeline.refine.kinematics import ChainModel, start_points
from pipeline.refine.orientation import OrientationRows, start_rotation
from pipeline.refine.points import PointBlock, with_reading_noise
from pipeline.refine.solve import Problem, chunks
from pipeline.sweeps import TOOL_SWEEP, sweep_name

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
    groups += ["tool_rotation"] * (3 * model.tool_rotation) + list(model.terms.groups)
    for name in block.param_names:
        head = name.split(".")[0].split("_")[0]
        groups.append(head if head in BLOCK_GROUPS else "sensor")
    names += list(block.param_names)
    units = (*model.param_units, *block.param_units)
    return tuple(names), tuple(units), tuple(groups)


def check_coverage(
    sweep: npt.NDArray[np.int64], n: int, prismatic: npt.NDArray[np.bool_], source: str
) -> None:
    """Refuse a session whose joint sweep or tool measurement has too few usable positions
    for the model (a revolute axis needs 3 positions, a prismatic line 2, the tool 1);
    ``sweep`` (K,): the sweep of each usable position."""
    for s in range(0, n + 1):
        need = 1 if s == TOOL_SWEEP else (2 if prismatic[s - 1] else 3)
        have = int((sweep == s).sum())
        if have < need:
            what = "the tool measurement" if s == TOOL_SWEEP else f"sweep {sweep_name(s)}"
            raise StageError(
                f"{source}: {what} has {have} usable positions",
                expected=f"at least {need} to refine the chain",
                got=f"{have} (the others null: no usable measurement)",
                fix="re-record that sweep, or --param refine.enabled=false",
            )


def reading_tangents(model: ChainModel, x: Array) -> Array:
    """``∂p/∂q_k`` (K, n, 3) of every key's position, by central differences of the model
    in its joint values (step 1e-6 rad / cm: the positions are smooth; only a weight).
    Where the joints sit at ``θ`` itself (no non-geometric deflection at ``x``: no terms,
    or ``β = 0``, the fit's start) the same differences by
    :meth:`ChainModel.joint_differences`, which moves one joint's motion at a time."""
    h = 1e-6
    if not (model.terms and np.asarray(x, float)[model.beta_slice].any()):
        return model.joint_differences(x, h)
    out = np.zeros((model.theta.shape[0], model.theta.shape[1], 3))
    for k in range(model.theta.shape[1]):
        step = np.zeros_like(model.theta)
        step[:, k] = h
        up = replace(model, theta=model.theta + step).positions(x)
        down = replace(model, theta=model.theta - step).positions(x)
        out[:, k] = (up - down) / (2.0 * h)
    return out


def chunked_start_points(model: ChainModel, measured: Array) -> Array:
    """:func:`pipeline.refine.kinematics.start_points` (n_points, 3) a chunk of
    observations at a time (:func:`pipeline.refine.solve.chunks`: never the (K, n, 4, 4)
    motions of every observation at once): each chunk's mean of the points it sees,
    weighed by their usable observations; the whole at once when one chunk holds them."""
    parts = chunks(model, keep=False)
    if len(parts) == 1:
        return start_points(model, measured)
    ok = np.asarray(np.isfinite(measured).all(axis=1), bool)
    total, count = np.zeros((model.n_points, 3)), np.zeros(model.n_points)
    for at, sub in parts:
        rows = np.flatnonzero(ok[at])
        seen = np.unique(sub.point[rows])
        if not len(rows):
            continue
        index = np.zeros(model.n_points, np.int64)
        index[seen] = np.arange(len(seen))
        names = tuple(model.point_names[j] for j in seen)
        part = replace(sub.observing(rows), point=index[sub.point[rows]], point_names=names)
        n = np.bincount(part.point, minlength=len(seen))
        total[seen] += start_points(part, measured[at][rows]) * n[:, None]
        count[seen] += n
    for j in np.flatnonzero(count == 0):  # its one-line error, as for the whole
        none = np.flatnonzero(model.point == j)[:1]
        part = replace(model.observing(none), point=np.zeros(len(none), np.int64),
                       point_names=(model.point_names[j],))  # fmt: skip
        start_points(part, np.full((len(none), 3), np.nan))
    return total / count[:, None]


def chain_problem(
    model: ChainModel,
    block: MeasurementBlock,
    measured: Array,
    loss: str,
    f_scale: float,
    reading_var: Array,
    orientation: OrientationRows | None = None,
) -> SessionProblem:
    """The problem of ``model`` fitted to ``block`` and its start: the thesis frames
    (``δ = 0``) and the target points they imply from the ``measured`` positions (K, 3) at
    the model's keys (NaN where none). A :class:`PointBlock` weighs the encoder readings'
    noise too, ``reading_var`` (n,) their variances (internal units: rad², cm²).
    ``orientation``: measured tool orientations (the model then has ``tool_rotation``,
    started at :func:`pipeline.refine.orientation.start_rotation`)."""
    p0 = chunked_start_points(model, measured)
    kin = np.concatenate(
        [
            np.zeros(model.n_axis_params),
            p0.ravel(),
            np.zeros(3 * model.tool_rotation + model.terms.size),
        ]
    )
    if orientation is not None:
        kin[model.rotation_slice] = start_rotation(model, kin, orientation)
    if isinstance(block, PointBlock):
        tangents = np.concatenate(  # a chunk at a time: the same bits (issue 45)
            [reading_tangents(sub, kin) for _, sub in chunks(model, keep=False)]
        )
        block = with_reading_noise(block, tangents, reading_var)
    x0 = np.concatenate([kin, block.x0])
    names, units, groups = parameter_labels(model, block)
    problem = Problem(model, block, loss, f_scale, orientation=orientation)
    return SessionProblem(problem, x0, model.point_names, names, units, groups)
