"""Joint limits in control (issue 30, item 1): a solution of the requested branch inside
the limits when one exists, else the status ``out_of_limits``.

A pose has, on one configuration branch, several joint vectors that differ only by
equivalences of the robot's geometry: any revolute joint turned by ±2π, and, for a
spherical wrist, the *wrist flip* ``(θ4 + π, −θ5, θ6 + π)`` of its last three joints
(exact for the design model, nearly so for a signature, whose solution is polished from
the flipped start by Newton-Raphson). The solvers of :class:`pipeline.control.Controller`
return the first of these inside the limits: the solution itself (shifted by ±2π), then
its wrist flip (shifted by ±2π). A converged solution with none inside gets
:data:`~pipeline.kinematics.ik.result.STATUS_OUT_OF_LIMITS` (not converged: ``ik``
exits 3), its joints unchanged so the caller can see which joint is outside.

The Puma's branch names the wrist flag too (``noflip``/``flip``, the sign of θ5). The
wrist flag of a requested branch is a preference: the flipped wrist is taken only when
the preferred one is outside the limits and the flipped one inside (the two are the same
arm configuration), and the Puma's solvers flag it
(:attr:`~pipeline.kinematics.ik.result.IKResult.branch_changed`: the answer's wrist flag
is not the requested one; issue 45). The compiled real-time solver does the same in its
kernel (:func:`pipeline.control.puma560_newton._solve_realtime`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.ik import STATUS_CONVERGED, STATUS_OUT_OF_LIMITS, IKResult, newton_raphson
from pipeline.kinematics.ik.batch import BoolArray
from pipeline.kinematics.transforms import Array, wrap_angle
from pipeline.robots.description import RobotDescription
from pipeline.robots.puma560 import NEAR_WRIST_SINGULAR, WRIST_TURNS
from pipeline.units import joints_to_internal

Limits = tuple[Array, Array, Array]

#: Configurations :func:`wrist_flip_applies` compares the flip at, and its tolerance (cm).
FLIP_SAMPLES = 8
FLIP_TOL_CM = 1e-9


def limit_arrays(robot: RobotDescription) -> Limits:
    """Lower and upper limits (n,) in rad / cm, and the turn (n,): 2π, or 0 for prismatic
    joints."""
    lower, upper = joints_to_internal(robot.limits.T, robot.prismatic)
    return lower, upper, np.where(robot.prismatic, 0.0, 2.0 * np.pi)


def shift_into(q: Array, lower: Array, upper: Array, turn: Array) -> None:
    """Revolute joints of ``q`` (m, n) shifted by ±2π in place where that brings them inside
    the limits of :func:`limit_arrays`."""
    outside = (q < lower) | (q > upper)
    if not np.count_nonzero(outside):  # the common case
        return
    for shift in (turn, -turn):
        moved = q + shift
        take = outside & (moved >= lower) & (moved <= upper)
        np.copyto(q, moved, where=take)
        outside &= ~take


def into_limits(robot: RobotDescription, q: Array) -> Array:
    """Revolute joints (m, n) in rad shifted by ±2π where that brings them inside the limits."""
    out = np.array(q, float)
    shift_into(out, *limit_arrays(robot))
    return out


def outside_mask(q: Array, limits: Limits) -> BoolArray:
    """Which joints of ``q`` (m, n) lie outside the limits, (m, n) bool."""
    lower, upper, _ = limits
    mask: BoolArray = (q < lower) | (q > upper)
    return mask


def outside_names(robot: RobotDescription, q: Array) -> list[tuple[str, ...]]:
    """The names of the joints outside the limits, per row of ``q`` (m, n) in rad / cm
    (joint values, the solvers' test: :func:`outside_mask`)."""
    mask = outside_mask(np.atleast_2d(q), limit_arrays(robot))
    names = [j.name for j in robot.joints]
    return [tuple(n for n, out in zip(names, row, strict=True) if out) for row in mask]


def wrist_flipped(q: Array) -> Array:
    """The wrist flip ``(θ4 + π, −θ5, θ6 + π)`` of the last three joints of ``q`` (m, n)."""
    out = np.array(q, float)
    out[:, -3] += np.pi
    out[:, -2] *= -1.0
    out[:, -1] += np.pi
    return out


def wrist_flip_applies(design: SerialChain) -> bool:
    """Whether the wrist flip is an equivalence of the ``design`` chain: its last three
    joints are revolute and the flip keeps the tool pose (to :data:`FLIP_TOL_CM`, and the
    rotation to the same relative size) at :data:`FLIP_SAMPLES` seeded configurations."""
    n = design.n_joints
    if n < 6 or design.prismatic[-3:].any():
        return False
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (FLIP_SAMPLES, n))
    T, T_flip = forward_kinematics(design, q), forward_kinematics(design, wrist_flipped(q))
    dp = np.abs(T[:, :3, 3] - T_flip[:, :3, 3]).max()
    dr = np.abs(T[:, :3, :3] - T_flip[:, :3, :3]).max()
    return bool(dp < FLIP_TOL_CM and dr < FLIP_TOL_CM / design.length_scale)


def _restarts(q: Array) -> list[Array]:
    """The starts :func:`honour_limits` tries from solutions ``q`` (m, n) outside the limits:
    the wrist flip, then the :data:`~pipeline.robots.puma560.WRIST_TURNS` of θ4
    against θ6."""
    starts = [wrist_flipped(q)]
    for turn in WRIST_TURNS:
        start = q.copy()
        start[:, -3] += turn
        start[:, -1] -= turn
        starts.append(start)
    return starts


def honour_limits(
    res: IKResult,
    chain: SerialChain,
    T: Array,
    limits: Limits,
    resolution: Array,
    flip: bool,
    task_axes: tuple[int, ...] | None = None,
    arm: Callable[[Array], Array] | None = None,
    near: Array | None = None,
) -> IKResult:
    """``res`` with every converged solution inside the limits when one of its
    equivalents is (module docstring), else marked ``out_of_limits``.

    ``chain`` and ``T`` (m, 4, 4): the model and the targets ``res`` solved (same frame);
    ``flip``: whether the wrist flip is an equivalence (:func:`wrist_flip_applies`; then
    a solution next to the wrist singularity also gets the
    :data:`~pipeline.robots.puma560.WRIST_TURNS` restarts); ``task_axes``: those of the
    solve (None: the full pose); ``arm``: the arm's branch flags of joints (m, n) ->
    (m, k), which a restart must keep (None: any); ``near`` (n,) or (m, n): the start
    configurations, whose 2π class a restart's solution takes before the shift, as the
    design start's (None: the solution's own).
    The joints of ``res`` are shifted in place; a solution found by a restart
    replaces its row's joints and errors, and every restart adds its iterations.
    """
    shift_into(res.q, *limits)
    bad = np.flatnonzero(res.converged & outside_mask(res.q, limits).any(axis=1))
    if not bad.size:
        return res
    q, status = res.q, res.status.copy()
    iterations = res.iterations.copy()
    errors = np.stack([res.position_error_cm, res.orientation_error_rad], axis=1)
    if flip:
        first = q[bad].copy()
        flags = None if arm is None else arm(first)
        near_singular = np.abs(np.sin(first[:, -2])) < NEAR_WRIST_SINGULAR
        left = np.ones(bad.size, bool)
        for k, start in enumerate(_restarts(first)):
            sel = np.flatnonzero(left if k == 0 else left & near_singular)
            if not sel.size:
                continue
            again = newton_raphson(chain, T[bad[sel]], start[sel], resolution,
                                   task_axes=task_axes)  # fmt: skip
            if near is not None:
                ref = np.broadcast_to(near, q.shape)[bad[sel]]
                turned = limits[2] > 0
                again.q[:, turned] = ref[:, turned] + wrap_angle(again.q - ref)[:, turned]
            shift_into(again.q, *limits)
            good = again.converged & ~outside_mask(again.q, limits).any(axis=1)
            if flags is not None:
                good &= np.all(arm(again.q) == flags[sel], axis=1)  # type: ignore[misc]
            rows = bad[sel[good]]
            q[rows] = again.q[good]
            iterations[bad[sel]] += again.iterations
            errors[rows, 0] = again.position_error_cm[good]
            errors[rows, 1] = again.orientation_error_rad[good]
            left[sel[good]] = False
        bad = bad[left]
    status[bad] = STATUS_OUT_OF_LIMITS
    return replace(
        res,
        converged=status == STATUS_CONVERGED,
        status=status,
        iterations=iterations,
        position_error_cm=errors[:, 0],
        orientation_error_rad=errors[:, 1],
    )
