"""Compiled Puma 560 control: the design-model start (Appendix B.2) and the
Newton-Raphson solve (5.4) of the signature in one kernel per target.

:class:`.puma560_solver.PumaSolver` is the pre-bound solver behind
:meth:`pipeline.control.Controller.solve` (Newton-Raphson, full pose) and its
real-time API :meth:`~pipeline.control.Controller.realtime`. Per target the
kernel computes, without Python objects:

1. the flange pose in D-H frame 0, ``X⁻¹_0 · X · T_base · Y⁻¹`` (``X``: design
   base to sensor, ``X_0``: the design chain's base in the sensor frame, ``Y``:
   flange to signature tool);
2. the closed-form design inverse on the requested branch, pulled onto the
   design workspace where the pose lies outside it
   (:func:`pipeline.control.puma560_inverse._puma_clamp`'s rule and margins),
   with θ4 kept from ``q_near`` at a wrist singularity and every joint in the
   2π class nearest ``q_near`` (:func:`~pipeline.control.puma560_inverse.puma_design_inverse`);
3. the Newton-Raphson / Levenberg-Marquardt iteration of
   :mod:`pipeline.kinematics.ik_compiled` from that start.

The start agrees with the numpy design inverse to round-off (~1e-15 rad; tested),
not bit for bit, so every Puma solve of a controller goes through this kernel:
one target and a batch then give the same bits. Targets the kernel defers
(:data:`~pipeline.kinematics.ik_compiled.FAST_DEFERRED`) are finished by the
numpy iteration from the kernel's start (:func:`pipeline.kinematics.ik.newton.finish_deferred`).
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.control.puma560_start import (
    NO_START,
    _design_start,
    _inside,
    _into_limits,
    _on_branch,
    _same_arm,
    _to_sensor,
    _wrap,
)
from pipeline.kinematics.ik_compiled import (
    FAST_CONVERGED,
    FAST_DEFERRED,
    Buf,
    Work,
    _errors,
    jit,
    jit_views,
    solve_one_target,
    workspace,
)
from pipeline.robots.puma560 import NEAR_WRIST_SINGULAR, WRIST_TURNS

#: Kernel outcome: converged, but on another branch than requested (flagged:
#: :attr:`pipeline.kinematics.ik.result.IKResult.branch_changed`).
OFF_BRANCH = 3
#: Kernel outcomes: converged (on the requested branch, or on another: flagged as
#: :data:`OFF_BRANCH`), but neither the solution nor its wrist flip is inside the joint
#: limits after the ±2π shift (:mod:`pipeline.control.limits`); ``q`` holds the solution.
OUT_OF_LIMITS, OUT_OF_LIMITS_OFF_BRANCH = 4, 5


#: Restarts (fallback step 2, see :class:`.puma560_solver.PumaSolver`), imported from
#: :data:`pipeline.robots.puma560.WRIST_TURNS`: θ4 turned by each angle and θ6 by its
#: negative, which keeps θ4 + θ6 and so the pose at the wrist singularity. Near it (θ5
#: within ~2°) the design start fixes θ4 + θ6 but not θ4 alone: with 0.03° of model
#: error the signature's θ4 can lie 1-2 rad from the design's, behind a local minimum of
#: the residual at θ5 ≈ 0. Measured on robot3 (100,000 targets of one branch): all 73
#: targets the first solve left unsolved converge from one of the first four, in 4-15
#: iterations. The same turns restart a solution outside the joint limits there.


@jit_views
def _solve_target(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf, target: Buf, Tw: Buf,
    spare: Buf, ws: Work,
) -> tuple[int, int]:  # fmt: skip
    """One target ``T_base`` (4, 4) in the design base frame: ``target = X · T_base``
    (sensor frame), the start ``q0`` from ``q_near`` and the solution ``q`` (6,),
    by the fallback order of :class:`.puma560_solver.PumaSolver` (steps 1-4). Returns the outcome
    (converged, :data:`OFF_BRANCH`, deferred or :data:`.puma560_start.NO_START`) and the
    iterations of all solves; ``Tw`` (4, 4), ``spare`` (2, 6), ``ws``
    (:func:`~pipeline.kinematics.ik_compiled.workspace`): scratch."""
    _to_sensor(X, T_base, target)
    if not _design_start(pre, post, branch, margins, target, q_near, q0, Tw):
        return NO_START, 0
    found = False  # a converged solution on another branch, kept in spare
    total = 0
    for attempt in range(WRIST_TURNS.shape[0] + 1):
        for j in range(q.shape[0]):
            q[j] = q0[j]
        if attempt:
            q[3] += WRIST_TURNS[attempt - 1]
            q[5] -= WRIST_TURNS[attempt - 1]
        outcome, it = solve_one_target(
            base, links, tool, offsets, prismatic, target, q, res, limit, settings, delta, ws
        )
        total += it
        if outcome == FAST_CONVERGED:
            if _on_branch(q, branch):
                return FAST_CONVERGED, total
            if not found:
                found = True
                for j in range(6):
                    spare[0, j], spare[1, j] = q[j], delta[j]
    if found:
        for j in range(6):
            q[j], delta[j] = spare[0, j], spare[1, j]
        return OFF_BRANCH, total
    return FAST_DEFERRED, total


@jit_views
def _restart_into_limits(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf, res: Buf, limit: Buf,
    settings: Buf, target: Buf, q_near: Buf, q: Buf, delta: Buf, spare: Buf, ws: Work,
    info: Buf, lower: Buf, upper: Buf, turn: Buf, branch: Buf,
) -> None:  # fmt: skip
    """A converged solution ``q`` outside the limits: Newton-Raphson from its wrist flip
    ``(θ4 + π, −θ5, θ6 + π)``, then (next to the wrist singularity) from its
    :data:`WRIST_TURNS`, the first converged one on the same arm branch inside the limits
    once in the 2π class nearest ``q_near`` and shifted by ±2π
    (:func:`pipeline.control.limits.honour_limits`, in numpy); one whose wrist flag
    is not ``branch``'s (the flip's, or a turn's across θ5 = 0) makes ``info[0]``
    :data:`OFF_BRANCH` (flagged: issue 45 found 14 of 100,000 such answers unflagged).
    None: ``q`` and δ kept, ``info[0]`` set to :data:`OUT_OF_LIMITS` (or
    :data:`OUT_OF_LIMITS_OFF_BRANCH`); ``info[1]`` counts every restart's iterations."""
    for j in range(6):
        spare[0, j], spare[1, j] = q[j], delta[j]
    near_singular = abs(math.sin(spare[0, 4])) < NEAR_WRIST_SINGULAR
    for attempt in range(WRIST_TURNS.shape[0] + 1):
        if attempt and not near_singular:
            break
        for j in range(6):
            q[j] = spare[0, j]
        if attempt:
            q[3] += WRIST_TURNS[attempt - 1]
            q[5] -= WRIST_TURNS[attempt - 1]
        else:
            q[3] += math.pi
            q[4] = -q[4]
            q[5] += math.pi
        outcome, it = solve_one_target(
            base, links, tool, offsets, prismatic, target, q, res, limit, settings, delta, ws
        )
        info[1] += it
        if outcome == FAST_CONVERGED:
            for j in range(6):  # the 2π class nearest q_near, as the design start's
                q[j] = q_near[j] + _wrap(q[j] - q_near[j])
            _into_limits(q, lower, upper, turn)
            if _inside(q, lower, upper) and _same_arm(q, spare[0]):
                if not _on_branch(q, branch):
                    info[0] = OFF_BRANCH
                return
    for j in range(6):
        q[j], delta[j] = spare[0, j], spare[1, j]
    info[0] = OUT_OF_LIMITS if info[0] == FAST_CONVERGED else OUT_OF_LIMITS_OFF_BRANCH


@jit
def _solve_targets(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf,
    outcome: Buf, iterations: Buf, errors: Buf, lower: Buf, upper: Buf, turn: Buf,
) -> None:  # fmt: skip
    """:func:`_solve_realtime` for each of ``T_base`` (m, 4, 4); outputs by row
    (``errors`` (m, 2): position cm, rotation rad). Allocates the scratch (the target in
    the sensor frame too: not kept, :meth:`.puma560_solver.PumaSolver.finish` forms it for
    the rows it needs); :func:`_solve_rows` loops (without reference counting: its views
    of each row)."""
    Tw, spare, ws = np.empty((4, 4)), np.empty((2, 6)), workspace(q.shape[1])
    target = np.empty((4, 4))
    _solve_rows(
        base, links, tool, offsets, prismatic, pre, post, branch, margins, res, limit,
        settings, X, T_base, q_near, q0, q, delta, target, outcome, iterations, errors,
        lower, upper, turn, Tw, spare, ws, np.empty(2, np.int64),
    )  # fmt: skip


@jit_views
def _solve_rows(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf, target: Buf,
    outcome: Buf, iterations: Buf, errors: Buf, lower: Buf, upper: Buf, turn: Buf,
    Tw: Buf, spare: Buf, ws: Work, info: Buf,
) -> None:  # fmt: skip
    """:func:`_solve_targets`' loop over the rows, with its scratch (``target`` (4, 4))."""
    for k in range(T_base.shape[0]):
        _solve_realtime(
            base, links, tool, offsets, prismatic, pre, post, branch, margins, res, limit,
            settings, X, T_base[k], q_near[k], q0[k], q[k], delta[k], target, Tw, spare,
            ws, info, errors[k], lower, upper, turn,
        )  # fmt: skip
        outcome[k], iterations[k] = info[0], info[1]


@jit_views
def _solve_realtime(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf, target: Buf, Tw: Buf,
    spare: Buf, ws: Work, info: Buf, errors: Buf, lower: Buf, upper: Buf, turn: Buf,
) -> None:  # fmt: skip
    """:func:`_solve_target` of one target, then the joint limits of a converged solution
    (:mod:`pipeline.control.limits`): shifted by ±2π, else its wrist flip polished by
    Newton-Raphson and shifted, else :data:`OUT_OF_LIMITS` (or
    :data:`OUT_OF_LIMITS_OFF_BRANCH`) with the solution kept; ``info`` (2,) receives
    the outcome and the iteration count, ``errors`` (2,) the position (cm) and rotation
    (rad) error of δ."""
    info[0], info[1] = _solve_target(
        base, links, tool, offsets, prismatic, pre, post, branch, margins, res, limit,
        settings, X, T_base, q_near, q0, q, delta, target, Tw, spare, ws,
    )  # fmt: skip
    if info[0] == FAST_CONVERGED or info[0] == OFF_BRANCH:
        _into_limits(q, lower, upper, turn)
        if not _inside(q, lower, upper):
            _restart_into_limits(base, links, tool, offsets, prismatic, res, limit, settings,
                                 target, q_near, q, delta, spare, ws, info, lower, upper,
                                 turn, branch)  # fmt: skip
    errors[0], errors[1] = _errors(delta)


#: :class:`.puma560_solver.PumaSolver`'s constant arrays packed into one float array, in this order
#: (six joints): base, links, tool, offsets, pre, post, branch, margins, resolution,
#: step cap, settings, X, lower and upper limits, turn. One array instead of 15,
#: because numba's dispatch costs ~0.18 µs per array argument (measured: a call of 32
#: arrays 5.8 µs, of 4 arrays 1.1 µs), more than the kernel's own work on one target.
_PACK_SIZES = (16, 96, 16, 6, 16, 16, 3, 2, 6, 6, 4, 16, 6, 6, 6)
(_P_BASE, _P_LINKS, _P_TOOL, _P_OFFSETS, _P_PRE, _P_POST, _P_BRANCH, _P_MARGINS, _P_RES,
 _P_LIMIT, _P_SETTINGS, _P_X, _P_LOWER, _P_UPPER, _P_TURN, _P_END) = (
    np.cumsum((0, *_PACK_SIZES)).tolist())  # fmt: skip
#: Its scratch packed likewise: q0, q, δ, errors, target, Tw, spare (2, 6), then the
#: :func:`~pipeline.kinematics.ik_compiled.workspace` T, J, M, dq, q_new, δ_new, J_new, A,
#: Am, g, r, Js, trig, trig_new.
_SCRATCH_SIZES = (6, 6, 6, 2, 16, 16, 12, 16, 36, 42, 6, 6, 6, 36, 36, 36, 6, 6, 36, 12, 12)
(_S_Q0, _S_Q, _S_DELTA, _S_ERRORS, _S_TARGET, _S_TW, _S_SPARE, _S_T, _S_J, _S_M, _S_DQ,
 _S_QNEW, _S_DNEW, _S_JNEW, _S_A, _S_AM, _S_G, _S_R, _S_JS, _S_TRIG, _S_TRIG_NEW,
 _S_END) = np.cumsum((0, *_SCRATCH_SIZES)).tolist()  # fmt: skip


@jit_views
def _solve_packed(
    P: Buf, prismatic: Buf, S: Buf, info: Buf, T_base: Buf, q_near: Buf
) -> None:  # fmt: skip
    """:func:`_solve_realtime` of one target with the model ``P`` and the scratch ``S``
    packed (:data:`_PACK_SIZES`, :data:`_SCRATCH_SIZES`): views, nothing allocated."""
    ws = (S[_S_T:_S_J].reshape(4, 4), S[_S_J:_S_M].reshape(6, 6), S[_S_M:_S_DQ].reshape(6, 7),
          S[_S_DQ:_S_QNEW], S[_S_QNEW:_S_DNEW], S[_S_DNEW:_S_JNEW],
          S[_S_JNEW:_S_A].reshape(6, 6), S[_S_A:_S_AM].reshape(6, 6),
          S[_S_AM:_S_G].reshape(6, 6), S[_S_G:_S_R], S[_S_R:_S_JS],
          S[_S_JS:_S_TRIG].reshape(6, 6), S[_S_TRIG:_S_TRIG_NEW].reshape(2, 6),
          S[_S_TRIG_NEW:_S_END].reshape(2, 6))  # fmt: skip
    _solve_realtime(
        P[_P_BASE:_P_LINKS].reshape(4, 4), P[_P_LINKS:_P_TOOL].reshape(6, 4, 4),
        P[_P_TOOL:_P_OFFSETS].reshape(4, 4), P[_P_OFFSETS:_P_PRE], prismatic,
        P[_P_PRE:_P_POST].reshape(4, 4), P[_P_POST:_P_BRANCH].reshape(4, 4),
        P[_P_BRANCH:_P_MARGINS], P[_P_MARGINS:_P_RES], P[_P_RES:_P_LIMIT],
        P[_P_LIMIT:_P_SETTINGS], P[_P_SETTINGS:_P_X], P[_P_X:_P_LOWER].reshape(4, 4),
        T_base, q_near, S[_S_Q0:_S_Q], S[_S_Q:_S_DELTA], S[_S_DELTA:_S_ERRORS],
        S[_S_TARGET:_S_TW].reshape(4, 4), S[_S_TW:_S_SPARE].reshape(4, 4),
        S[_S_SPARE:_S_T].reshape(2, 6), ws, info, S[_S_ERRORS:_S_TARGET],
        P[_P_LOWER:_P_UPPER], P[_P_UPPER:_P_TURN], P[_P_TURN:_P_END],
    )  # fmt: skip
