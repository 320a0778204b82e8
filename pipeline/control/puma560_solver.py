"""Compiled Puma 560 control: the design-model start (Appendix B.2) and the
Newton-Raphson solve (5.4) of the signature in one kernel per target.

:class:`PumaSolver` is the pre-bound solver behind
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
numpy iteration from the kernel's start (:func:`pipeline.kinematics.ik.finish_deferred`).
"""

from __future__ import annotations

import math

import numpy as np

from pipeline.kinematics import ik
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.ik_compiled import (
    FAST_CONVERGED,
    FAST_DEFERRED,
    Buf,
    IntArray,
    Work,
    _delta,
    _errors,
    homogeneous,
    inline_jit,
    jit,
    pose,
    run_in_shares,
    solve_one_target,
    workspace,
)
from pipeline.kinematics.ik_stall import STALL_RATIO
from pipeline.kinematics.transforms import Array, differential_motion, invert_transform
from pipeline.robots import puma560
from pipeline.robots.puma560 import Branch

#: Kernel outcome: the design inverse has no start (the clamped pose is still out
#: of reach; not met with finite poses, kept so no NaN reaches the iteration).
NO_START = 2

_D1, _D3, _, _D4, _, _D6 = puma560.DESIGN_D_CM
_A2, _A3 = puma560.DESIGN_A_CM[1], puma560.DESIGN_A_CM[2]
_RHO2 = _D4**2 + _A3**2
_PHI = math.atan2(_A3, _D4)
_TWO_PI = 2.0 * math.pi
_SINGULAR = puma560.WRIST_SINGULAR_TOL


@inline_jit
def _wrap(t: float) -> float:
    """:func:`pipeline.kinematics.transforms.wrap_angle` of one angle: (-π, π]."""
    a = math.pi - t
    # np.mod(a, 2π) is a itself for 0 <= a < 2π (fmod is exact): skip its call there
    return math.pi - (a if 0.0 <= a < _TWO_PI else np.mod(a, _TWO_PI))


@inline_jit
def _design_start(
    pre: Buf, post: Buf, branch: Buf, margins: Buf, target: Buf, q_near: Buf, q: Buf, Tw: Buf
) -> bool:
    """The design inverse of one target into ``q`` (6,) (module docstring, steps 1-2).

    ``pre``, ``post`` (4, 4): world (sensor) to D-H frame 0 and tool to flange;
    ``branch`` (3,): shoulder, elbow, wrist flags (±1); ``margins`` (2,): the clamp's
    elbow margin (rad) and shoulder margin (cm); ``Tw`` (4, 4): scratch.
    False when even the clamped pose has no solution.
    """
    for r in range(4):  # Tw = (pre · target) · post, as puma_design_inverse
        for c in range(4):
            Tw[r, c] = (pre[r, 0] * target[0, c] + pre[r, 1] * target[1, c]
                        + pre[r, 2] * target[2, c] + pre[r, 3] * target[3, c])  # fmt: skip
    for r in range(4):
        a0, a1, a2, a3 = Tw[r, 0], Tw[r, 1], Tw[r, 2], Tw[r, 3]
        for c in range(4):
            Tw[r, c] = a0 * post[0, c] + a1 * post[1, c] + a2 * post[2, c] + a3 * post[3, c]
    wx, wy, wz = (Tw[0, 3] - _D6 * Tw[0, 2], Tw[1, 3] - _D6 * Tw[1, 2],
                  Tw[2, 3] - _D6 * Tw[2, 2])  # fmt: skip  # the wrist centre
    px, py, pz = wx, wy, wz - _D1
    rr = px**2 + py**2 - _D3**2
    root_rr = math.sqrt(max(rr, 0.0))
    Kc = (root_rr**2 + pz**2 - (_D4**2 + _A3**2 + _A2**2)) / (2.0 * _A2)  # (B.22)
    disc = (_D4**2 + _A3**2) - Kc**2
    if not (rr >= 0.0 and disc >= 0.0):  # _puma_clamp: onto the design workspace
        r_c = math.sqrt(max(px**2 + py**2 - _D3**2, margins[1] ** 2))
        D2 = r_c**2 + pz**2
        K_lim = math.sqrt(_RHO2) * math.cos(margins[0])
        K = min(max((D2 - _RHO2 - _A2**2) / (2.0 * _A2), -K_lim), K_lim)
        scale = math.sqrt((_RHO2 + _A2**2 + 2.0 * _A2 * K) / D2)
        r_new, pz_new = r_c * scale, pz * scale
        rad = math.hypot(px, py)
        ux, uy = (px / rad, py / rad) if rad > 0.0 else (1.0, 0.0)
        R_new = math.sqrt(r_new**2 + _D3**2)
        Tw[0, 3] += ux * R_new - wx
        Tw[1, 3] += uy * R_new - wy
        Tw[2, 3] += pz_new + _D1 - wz
        wx, wy, wz = (Tw[0, 3] - _D6 * Tw[0, 2], Tw[1, 3] - _D6 * Tw[1, 2],
                      Tw[2, 3] - _D6 * Tw[2, 2])  # fmt: skip
        px, py, pz = wx, wy, wz - _D1
        rr = px**2 + py**2 - _D3**2
        root_rr = math.sqrt(max(rr, 0.0))
        Kc = (root_rr**2 + pz**2 - (_D4**2 + _A3**2 + _A2**2)) / (2.0 * _A2)
        disc = (_D4**2 + _A3**2) - Kc**2
        if not (rr >= 0.0 and disc >= 0.0):
            return False
    # puma560.inverse_kinematics on one branch
    reach = branch[0] * root_rr
    t1 = math.atan2(py, px) - math.atan2(_D3, reach)
    t3 = math.atan2(Kc, branch[1] * math.sqrt(max(disc, 0.0))) - _PHI
    S3, C3 = math.sin(t3), math.cos(t3)
    u = _A2 + _D4 * S3 + _A3 * C3
    v = _D4 * C3 - _A3 * S3
    t2 = math.atan2(v * reach - u * pz, u * reach + v * pz)
    c1, s1, c23, s23 = math.cos(t1), math.sin(t1), math.cos(t2 + t3), math.sin(t2 + t3)
    # _wrist_rotation: R36 = R03ᵀ R06, the entries used, as scalars r_ij
    a0, a2 = c1 * Tw[0, 0] + s1 * Tw[1, 0], c1 * Tw[0, 2] + s1 * Tw[1, 2]
    r00, r02 = c23 * a0 - s23 * Tw[2, 0], c23 * a2 - s23 * Tw[2, 2]
    r10, r12 = c1 * Tw[1, 0] - s1 * Tw[0, 0], c1 * Tw[1, 2] - s1 * Tw[0, 2]
    r20, r22 = s23 * a0 + c23 * Tw[2, 0], s23 * a2 + c23 * Tw[2, 2]
    r21 = s23 * (c1 * Tw[0, 1] + s1 * Tw[1, 1]) + c23 * Tw[2, 1]
    w = branch[2]
    s5 = math.hypot(r02, r12)
    q[0], q[1], q[2] = t1, t2, t3
    q[4] = math.atan2(s5 if w > 0 else -s5, r22)
    q[3] = math.atan2(w * r12, w * r02)
    q[5] = math.atan2(w * r21, -(w * r20))
    if s5 < _SINGULAR:
        q[3] = 0.0
        if r22 > 0:
            q[5] = math.atan2(r10, r00)
        else:
            q[5] = math.atan2(r10, -r00)
    for j in range(6):
        q[j] = _wrap(q[j])
    # puma_design_inverse: θ4 from q_near at a wrist singularity, 2π class of q_near
    if abs(math.sin(q[4])) < _SINGULAR:
        t4 = q_near[3]
        if math.cos(q[4]) > 0:
            q[5] = q[5] + q[3] - t4
        else:
            q[5] = q[5] - q[3] + t4
        q[3] = t4
    for j in range(6):
        q[j] = q_near[j] + _wrap(q[j] - q_near[j])
    return True


@inline_jit
def _into_limits(q: Buf, lower: Buf, upper: Buf, turn: Buf) -> None:
    """``pipeline.control._shift_into`` of one configuration (6,), in place."""
    for j in range(q.shape[0]):
        if q[j] < lower[j] or q[j] > upper[j]:
            up, down = q[j] + turn[j], q[j] - turn[j]
            if lower[j] <= up <= upper[j]:
                q[j] = up
            elif lower[j] <= down <= upper[j]:
                q[j] = down


#: Kernel outcome: converged, but on another branch than requested (flagged:
#: :attr:`pipeline.kinematics.ik.IKResult.branch_changed`).
OFF_BRANCH = 3

#: Restarts (fallback step 3, see :class:`PumaSolver`): θ4 turned by each angle and
#: θ6 by its negative, which keeps θ4 + θ6 and so the pose at the wrist
#: singularity. Near it (θ5 within ~2°) the design start fixes θ4 + θ6 but not
#: θ4 alone: with 0.03° of model error the signature's θ4 can lie 1-2 rad from
#: the design's, behind a local minimum of the residual at θ5 ≈ 0. Measured on
#: robot3 (100,000 targets of one branch): all 73 targets the first solve left
#: unsolved converge from one of the first four, in 4-15 iterations.
WRIST_TURNS = np.array([1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0]) * (np.pi / 4.0)


@inline_jit
def _to_sensor(X: Buf, T_base: Buf, target: Buf) -> None:
    """``target = X · T_base`` (4, 4): a pose in the design base frame in the sensor frame."""
    for r in range(4):
        for c in range(4):
            target[r, c] = (X[r, 0] * T_base[0, c] + X[r, 1] * T_base[1, c]
                            + X[r, 2] * T_base[2, c] + X[r, 3] * T_base[3, c])  # fmt: skip


@inline_jit
def _on_branch(q: Buf, branch: Buf) -> bool:
    """:func:`pipeline.robots.puma560.branch_of` of ``q`` (6,) equals ``branch`` (3,)."""
    s23, c23 = math.sin(q[1] + q[2]), math.cos(q[1] + q[2])
    reach = _D4 * s23 + _A3 * c23 + _A2 * math.cos(q[1])
    elbow = math.cos(q[2] + _PHI)
    wrist = math.sin(q[4])
    return (
        (1.0 if reach >= 0 else -1.0) == branch[0]
        and (1.0 if elbow >= 0 else -1.0) == branch[1]
        and (1.0 if wrist >= 0 else -1.0) == branch[2]
    )


@jit
def _solve_target(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf, target: Buf, Tw: Buf,
    spare: Buf, ws: Work,
) -> tuple[int, int]:  # fmt: skip
    """One target ``T_base`` (4, 4) in the design base frame: ``target = X · T_base``
    (sensor frame), the start ``q0`` from ``q_near`` and the solution ``q`` (6,),
    by the fallback order of :class:`PumaSolver` (steps 1-4). Returns the outcome
    (converged, :data:`OFF_BRANCH`, deferred or :data:`NO_START`) and the
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


@jit
def _solve_targets(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf, target: Buf,
    outcome: Buf, iterations: Buf, errors: Buf, lower: Buf, upper: Buf, turn: Buf,
) -> None:  # fmt: skip
    """:func:`_solve_realtime` for each of ``T_base`` (m, 4, 4); outputs by row
    (``errors`` (m, 2): position cm, rotation rad)."""
    Tw, spare, ws = np.empty((4, 4)), np.empty((2, 6)), workspace(q.shape[1])
    info = np.empty(2, np.int64)
    for k in range(T_base.shape[0]):
        _solve_realtime(
            base, links, tool, offsets, prismatic, pre, post, branch, margins, res, limit,
            settings, X, T_base[k], q_near[k], q0[k], q[k], delta[k], target[k], Tw, spare,
            ws, info, errors[k], lower, upper, turn,
        )  # fmt: skip
        outcome[k], iterations[k] = info[0], info[1]


@jit
def _solve_realtime(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf, target: Buf, Tw: Buf,
    spare: Buf, ws: Work, info: Buf, errors: Buf, lower: Buf, upper: Buf, turn: Buf,
) -> None:  # fmt: skip
    """:func:`_solve_target` of one target, then the joint-limit shift of a converged
    solution; ``info`` (2,) receives the outcome and the iteration count, ``errors``
    (2,) the position (cm) and rotation (rad) error of δ."""
    info[0], info[1] = _solve_target(
        base, links, tool, offsets, prismatic, pre, post, branch, margins, res, limit,
        settings, X, T_base, q_near, q0, q, delta, target, Tw, spare, ws,
    )  # fmt: skip
    errors[0], errors[1] = _errors(delta)
    if info[0] == FAST_CONVERGED or info[0] == OFF_BRANCH:
        _into_limits(q, lower, upper, turn)


#: :class:`PumaSolver`'s constant arrays packed into one float array, in this order
#: (six joints): base, links, tool, offsets, pre, post, branch, margins, resolution,
#: step cap, settings, X, lower and upper limits, turn. One array instead of 15,
#: because numba's dispatch costs ~0.18 µs per array argument (measured: a call of 32
#: arrays 5.8 µs, of 4 arrays 1.1 µs), more than the kernel's own work on one target.
_PACK_SIZES = (16, 96, 16, 6, 16, 16, 3, 2, 6, 6, 4, 16, 6, 6, 6)
(_P_BASE, _P_LINKS, _P_TOOL, _P_OFFSETS, _P_PRE, _P_POST, _P_BRANCH, _P_MARGINS, _P_RES,
 _P_LIMIT, _P_SETTINGS, _P_X, _P_LOWER, _P_UPPER, _P_TURN, _P_END) = (
    np.cumsum((0, *_PACK_SIZES)).tolist())  # fmt: skip
#: Its scratch packed likewise: q0, q, δ, errors, target, Tw, spare (2, 6), then the
#: :func:`~pipeline.kinematics.ik_compiled.workspace` T, J, M, dq, q_new, δ_new.
_SCRATCH_SIZES = (6, 6, 6, 2, 16, 16, 12, 16, 36, 42, 6, 6, 6)
(_S_Q0, _S_Q, _S_DELTA, _S_ERRORS, _S_TARGET, _S_TW, _S_SPARE, _S_T, _S_J, _S_M, _S_DQ,
 _S_QNEW, _S_DNEW, _S_END) = np.cumsum((0, *_SCRATCH_SIZES)).tolist()  # fmt: skip


@jit
def _solve_packed(
    P: Buf, prismatic: Buf, S: Buf, info: Buf, T_base: Buf, q_near: Buf
) -> None:  # fmt: skip
    """:func:`_solve_realtime` of one target with the model ``P`` and the scratch ``S``
    packed (:data:`_PACK_SIZES`, :data:`_SCRATCH_SIZES`): views, nothing allocated."""
    ws = (S[_S_T:_S_J].reshape(4, 4), S[_S_J:_S_M].reshape(6, 6), S[_S_M:_S_DQ].reshape(6, 7),
          S[_S_DQ:_S_QNEW], S[_S_QNEW:_S_DNEW], S[_S_DNEW:_S_END])  # fmt: skip
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


#: Jacobi kernel outcomes besides converged: stalled (no progress in
#: :data:`~pipeline.kinematics.ik.JACOBI_STALL_PATIENCE` iterations), no design
#: inverse (both ``STATUS_UNREACHABLE``), and the iteration cap.
J_STALLED, J_NO_INVERSE, J_MAX_ITER = 4, 5, 6
_JACOBI_SLOW = ik.JACOBI_SLOW_RATIO
_JACOBI_PATIENCE = ik.JACOBI_STALL_PATIENCE
_ANDERSON_RCOND = ik.ANDERSON_RCOND
_STALL = STALL_RATIO
#: :func:`_jacobi_work`: scratch of one Jacobi solve (4 history, 6 pose, 5 vector buffers).
JacobiWork = tuple[Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf]


@jit
def _anderson(Qh: Buf, Gh: Buf, count: int, out: Buf, dF: Buf, dG: Buf, f: Buf) -> None:
    """:func:`pipeline.kinematics.ik._anderson` of one target: ``Qh``, ``Gh`` (h, n)
    oldest first, the last ``count`` rows valid; the accelerated iterate into ``out``.
    ``dF`` (n, h - 1), ``dG`` (h - 1, n), ``f`` (n,): scratch."""
    h, n = Qh.shape
    dF[:] = 0.0
    dG[:] = 0.0
    first = h - min(count, h)
    for j in range(first, h - 1):
        for i in range(n):
            dF[i, j] = (Gh[j + 1, i] - Qh[j + 1, i]) - (Gh[j, i] - Qh[j, i])
            dG[j, i] = Gh[j + 1, i] - Gh[j, i]
    for i in range(n):
        f[i] = Gh[h - 1, i] - Qh[h - 1, i]
    gamma = np.linalg.pinv(dF, _ANDERSON_RCOND) @ f
    for i in range(n):
        acc = Gh[h - 1, i]
        for j in range(h - 1):
            acc -= dG[j, i] * gamma[j]
        out[i] = acc


@inline_jit
def _jacobi_map(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    d_base: Buf, d_links: Buf, d_tool: Buf, d_offsets: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf,
    target: Buf, q: Buf, Ts: Buf, q_next: Buf, Tw: Buf, Td: Buf, Delta: Buf, Tk: Buf,
) -> bool:  # fmt: skip
    """(5.8): ``q_next = F_d⁻¹[F_d(q) · F_s(q)⁻¹ · T*]`` (``Ts``: F_s(q)); False when
    the design inverse has none. ``Tw``, ``Td``, ``Delta``, ``Tk`` (4, 4): scratch."""
    pose(d_base, d_links, d_tool, d_offsets, prismatic, q, Td)
    for r in range(3):  # Eq. (5.9): Δ = F_s(q)⁻¹ T*, C.2 step 4
        for c in range(4):
            acc = Ts[0, r] * target[0, c] + Ts[1, r] * target[1, c] + Ts[2, r] * target[2, c]
            if c == 3:
                acc -= Ts[0, r] * Ts[0, 3] + Ts[1, r] * Ts[1, 3] + Ts[2, r] * Ts[2, 3]
            Delta[r, c] = acc
    Delta[3, 0], Delta[3, 1], Delta[3, 2], Delta[3, 3] = 0.0, 0.0, 0.0, 1.0
    for r in range(4):  # Eq. (5.10): T^k = F_d(q) Δ, C.2 step 5
        for c in range(4):
            Tk[r, c] = (Td[r, 0] * Delta[0, c] + Td[r, 1] * Delta[1, c]
                        + Td[r, 2] * Delta[2, c] + Td[r, 3] * Delta[3, c])  # fmt: skip
    return _design_start(pre, post, branch, margins, Tk, q, q_next, Tw)  # C.2 step 6


@inline_jit
def _error_at(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    target: Buf, q: Buf, Ts: Buf, d: Buf, length: float,
) -> tuple[float, float, float]:  # fmt: skip
    """F_s(q) into ``Ts``, its δ into ``d``; the position and rotation errors and the
    scaled error."""
    pose(base, links, tool, offsets, prismatic, q, Ts)
    _delta(Ts, target, d)
    ep, eo = _errors(d)
    return ep, eo, ep * (1.0 / length) + eo


@jit
def _jacobi_work(n: int) -> JacobiWork:
    """Scratch of :func:`_jacobi_one` for ``n`` joints, made once per batch: the
    Anderson history Qh, Gh (n + 1, n) and its differences dF (n, n), dG (n, n);
    six (4, 4) poses; q_next, q_acc (n,), δ_new, δ_acc (6,), f (n,)."""
    h = n + 1
    return (
        np.zeros((h, n)), np.zeros((h, n)), np.zeros((n, h - 1)), np.zeros((h - 1, n)),
        np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)),
        np.empty((4, 4)), np.empty((4, 4)), np.empty(n), np.empty(n), np.empty(6),
        np.empty(6), np.empty(n),
    )  # fmt: skip


@inline_jit
def _jacobi_one(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    d_base: Buf, d_links: Buf, d_tool: Buf, d_offsets: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, settings: Buf,
    target: Buf, q: Buf, delta: Buf, Tw: Buf, work: JacobiWork,
) -> tuple[int, int]:  # fmt: skip
    """:func:`pipeline.kinematics.ik.jacobi_iterative` (``accelerate=True``) of one
    target from ``q`` (6,) (in: the start, out: the last iterate): (5.8) with the
    design inverse on ``branch`` nearest the iterate (``margins``: the Jacobi
    clamp margins); where an iterate's error falls by less than half, Anderson
    acceleration of the same map whenever it gives the smaller error; the
    encoder rule and the pose tolerances to stop; no progress in
    :data:`~pipeline.kinematics.ik.JACOBI_STALL_PATIENCE` iterations of
    accelerated steps, a stall. Returns the outcome and the iteration count; ``Tw``,
    ``work`` (:func:`_jacobi_work`): scratch."""
    n = q.shape[0]
    max_iter, length = int(settings[0]), settings[1]
    tol_p, tol_o = settings[2], settings[3]
    h = n + 1
    Qh, Gh, dF, dG, Ts, T_plain, T_acc, Td, Delta, Tk, q_next, q_acc, d_new, d_acc, f = work
    Qh[:] = 0.0
    Gh[:] = 0.0
    ep, eo, e = _error_at(base, links, tool, offsets, prismatic, target, q, Ts, delta, length)
    count, slow, idle = 0, False, 0
    for it in range(1, max_iter + 1):
        found = _jacobi_map(
            base, links, tool, offsets, prismatic, d_base, d_links, d_tool, d_offsets,
            pre, post, branch, margins, target, q, Ts, q_next, Tw, Td, Delta, Tk,
        )  # fmt: skip
        if not found:
            return J_NO_INVERSE, it - 1
        ep, eo, e_plain = _error_at(
            base, links, tool, offsets, prismatic, target, q_next, T_plain, d_new, length
        )
        taken = T_plain
        for k in range(h - 1):  # the history, oldest first
            for j in range(n):
                Qh[k, j], Gh[k, j] = Qh[k + 1, j], Gh[k + 1, j]
        for j in range(n):
            Qh[h - 1, j], Gh[h - 1, j] = q[j], q_next[j]
        count += 1
        e_new = e_plain
        was_slow = slow
        if was_slow:
            _anderson(Qh, Gh, count, q_acc, dF, dG, f)
            ap, ao, e_acc = _error_at(
                base, links, tool, offsets, prismatic, target, q_acc, T_acc, d_acc, length
            )
            if e_acc < e_new:  # never worse than (5.8)
                for j in range(n):
                    q_next[j] = q_acc[j]
                for r in range(6):
                    d_new[r] = d_acc[r]
                ep, eo, e_new = ap, ao, e_acc
                taken = T_acc
        slow = slow or e_plain > _JACOBI_SLOW * e
        small = True  # Appendix C.1 step 8 on the step taken
        for j in range(n):
            small = small and abs(q_next[j] - q[j]) < res[j]
        accurate = ep <= tol_p and eo <= tol_o
        stuck = was_slow and small and not (accurate or e_new < _STALL * e)
        idle = idle + 1 if stuck else 0
        for j in range(n):
            q[j] = q_next[j]
        for r in range(6):
            delta[r] = d_new[r]
        for r in range(4):
            for c in range(4):
                Ts[r, c] = taken[r, c]  # F_s at the new iterate
        e = e_new
        if small and accurate:
            return FAST_CONVERGED, it
        if idle >= _JACOBI_PATIENCE:
            return J_STALLED, it
    return J_MAX_ITER, max_iter


@jit
def _jacobi_targets(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, limit: Buf, settings: Buf,
    d_base: Buf, d_links: Buf, d_tool: Buf, d_offsets: Buf, j_margins: Buf,
    X: Buf, T_base: Buf, q_near: Buf, q0: Buf, q: Buf, delta: Buf, target: Buf,
    outcome: Buf, iterations: Buf,
) -> None:  # fmt: skip
    """Start (``margins``) and Jacobi iteration (``j_margins``) of each of ``T_base``
    (m, 4, 4) (design base frame); outputs by row as :func:`_solve_targets`."""
    Tw, work = np.empty((4, 4)), _jacobi_work(q.shape[1])
    for k in range(T_base.shape[0]):
        _to_sensor(X, T_base[k], target[k])
        if not _design_start(pre, post, branch, margins, target[k], q_near[k], q0[k], Tw):
            outcome[k], iterations[k] = NO_START, 0
            continue
        for j in range(q.shape[1]):
            q[k, j] = q0[k, j]
        outcome[k], iterations[k] = _jacobi_one(
            base, links, tool, offsets, prismatic, d_base, d_links, d_tool, d_offsets,
            pre, post, branch, j_margins, res, settings, target[k], q[k], delta[k], Tw, work,
        )  # fmt: skip


#: Templates of a one-target result's flags and status (:meth:`PumaSolver.solve`).
_ONE_TRUE, _ONE_FALSE = np.ones(1, bool), np.zeros(1, bool)
_ONE_ZERO = np.zeros(1, np.int64)


class PumaSolver:
    """Newton-Raphson from the Puma design start, bound to one signature and branch.

    Made by :meth:`pipeline.control.Controller.realtime` (or from the parts
    here). Every array the kernel reads is made once, contiguous, at
    construction; :meth:`solve_one` writes into buffers owned by the solver.

    Fallback order, per target, each step only where the previous one left the
    target unsolved or off the requested branch:

    1. Newton-Raphson (5.4) from the design start, Levenberg-Marquardt steps
       where a Newton step does not descend (:mod:`pipeline.kinematics.ik_compiled`);
    2. (branch-preserving) the same from the start with θ4 and θ6 turned
       against each other (:data:`WRIST_TURNS`), the first solution on the branch;
    3. (any branch, flagged) the first solution of 1-2 on another branch,
       with :attr:`~pipeline.kinematics.ik.IKResult.branch_changed` set;
    4. the numpy iteration of :func:`pipeline.kinematics.ik.newton_raphson`
       from the design start, which gives the status of a target it cannot
       solve either (its solution's branch flagged as in 3).

    Parameters
    ----------
    chain : SerialChain
        The signature chain (unbatched, six joints), sensor frame, cm.
    design_base, flange_to_tool : ndarray, shape (4, 4)
        The design chain's base in the sensor frame (``X · base``) and the flange
        to the signature tool ``Y``.
    sensor_from_base : ndarray, shape (4, 4)
        ``X``: design base frame to sensor frame (for :meth:`solve_one`).
    branch : Branch
    resolution : ndarray, shape (6,)
        Encoder resolution, rad.
    limits : tuple of ndarray
        Lower and upper joint limits and the turn (2π) per joint, rad
        (``pipeline.control._limit_arrays``).
    margins : tuple of float
        The design inverse's clamp margins (elbow rad, shoulder cm).
    design : SerialChain, optional
        The design model in the sensor frame with the signature's tool, for
        :meth:`solve_jacobi`.
    jacobi_margins : tuple of float
        The clamp margins of the design inverse inside the Jacobi iteration.
    """

    def __init__(
        self,
        chain: SerialChain,
        design_base: Array,
        flange_to_tool: Array,
        sensor_from_base: Array,
        branch: Branch,
        resolution: Array,
        limits: tuple[Array, Array, Array],
        margins: tuple[float, float],
        design: SerialChain | None = None,
        jacobi_margins: tuple[float, float] = (0.0, 0.0),
        max_iter: int = 50,
        position_tol_cm: float = 1e-7,
        orientation_tol_rad: float = 1e-10,
        max_step: float = 0.5,
    ) -> None:
        n = chain.n_joints
        if not ik.ik_compilable(chain) or chain.prismatic.any():
            raise ValueError("PumaSolver needs an unbatched six-revolute-joint chain")
        c = np.ascontiguousarray
        self.chain = chain
        self.branch = branch
        parts = (
            chain.base, chain.links, chain.tool, chain.joint_offsets,
            invert_transform(design_base), invert_transform(flange_to_tool),
            [branch.shoulder, branch.elbow, branch.wrist], margins,
            np.broadcast_to(resolution, (n,)), np.full(n, max_step),
            [max_iter, chain.length_scale, position_tol_cm, orientation_tol_rad],
            sensor_from_base, *limits,
        )  # fmt: skip
        #: Every constant array of the kernels, packed (:data:`_PACK_SIZES`); the
        #: arrays below are views of it.
        self._packed = np.concatenate([np.asarray(a, float).ravel() for a in parts])
        views = np.split(self._packed, np.cumsum(_PACK_SIZES)[:-1])
        shapes = ((4, 4), (n, 4, 4), (4, 4), (n,), (4, 4), (4, 4)) + ((-1,),) * 5
        model = [v.reshape(shape) for v, shape in zip(views, shapes, strict=False)]
        self._prismatic = c(chain.prismatic, np.bool_)
        model.insert(4, self._prismatic)
        self.resolution = model[9]
        self.settings = (max_iter, position_tol_cm, orientation_tol_rad, max_step)
        self._model = tuple(model)
        if design is not None and not homogeneous(design.base, design.links, design.tool):
            raise ValueError("PumaSolver needs a design chain of homogeneous transforms")
        self.design = design
        self._design = None if design is None else (
            c(design.base, float), c(design.links, float), c(design.tool, float),
            c(design.joint_offsets, float), np.array(jacobi_margins, float),
        )  # fmt: skip
        self._frames = (design_base, flange_to_tool)  # for the numpy design inverse
        self._X = views[11].reshape(4, 4)
        self._limits = (views[12], views[13], views[14])
        self._q_ref = c(chain.joint_offsets, float)  # q^s: the default q_near
        #: Scratch of :meth:`solve_one`, packed (:data:`_SCRATCH_SIZES`); the buffers
        #: below are views of it.
        self._scratch = np.empty(_S_END)
        S = self._scratch
        #: The last solution of :meth:`solve_one` (6,), rad; overwritten by the next call
        #: (before the first: q^s). May be passed back as ``q_near``.
        self.q = S[_S_Q:_S_DELTA]
        self.q[:] = self._q_ref
        #: The last start (the design inverse) of :meth:`solve_one` (6,), rad.
        self.q0 = S[_S_Q0:_S_Q]
        #: The last final δ of :meth:`solve_one` (6,): cm and rad.
        self.delta = S[_S_DELTA:_S_ERRORS]
        #: The last kernel outcome and iteration count of :meth:`solve_one`.
        self.info = np.zeros(2, np.int64)
        #: Whether the last solution of :meth:`solve_one` lies on another branch (step 3).
        self.branch_changed = False
        #: The last position (cm) and rotation (rad) error of :meth:`solve_one`.
        self.errors = S[_S_ERRORS:_S_TARGET]
        self._target = S[_S_TARGET:_S_TW].reshape(4, 4)
        #: :meth:`solve`'s scratch and outcome for one target (the real-time buffers
        #: above are :meth:`solve_one`'s alone).
        one = np.empty(_S_END)
        self._one = (one, np.zeros(2, np.int64), one[_S_Q:_S_DELTA].reshape(1, n),
                     one[_S_ERRORS:_S_TARGET])  # fmt: skip

    def solve_one(self, T_base: Array, q_near: Array | None = None) -> bool:
        """Solve one pose (4, 4) given in the design base frame; True when converged.

        The real-time call: no array is allocated when the kernel converges
        (all but ~1e-3 of random reachable targets); :attr:`q` then holds the
        joints (rad, shifted into the limits by ±2π where that helps, as
        :meth:`pipeline.control.Controller.solve`) and :attr:`info` the
        iteration count. ``q_near`` (6,), rad (contiguous float): the 2π class
        and, at a wrist singularity, θ4 of the start; default q^s (pass the
        previous solution in a trajectory). A target the kernel defers is
        finished by the numpy iteration (allocates; ~1 ms), with the same
        result as ``Controller.solve``.
        """
        near = self._q_ref if q_near is None else q_near
        _solve_packed(self._packed, self._prismatic, self._scratch, self.info, T_base, near)
        if self.info[0] == FAST_CONVERGED or self.info[0] == OFF_BRANCH:
            self.branch_changed = self.info[0] == OFF_BRANCH
            return True
        res = self.finish(self._target[None], near[None], self.q0[None], self.q[None].copy(),
                          self.info[:1].copy(), self.info[1:].copy(), self.delta[None],
                          self.errors[None].copy())  # fmt: skip
        self.q[:] = res.q[0]
        self.info[1] = res.iterations[0]
        self.branch_changed = bool(res.branch_changed is not None and res.branch_changed[0])
        return bool(res.converged[0])

    def solve(self, T_base: Array, q_near: Array | None = None) -> ik.IKResult:
        """Solve targets (m, 4, 4) given in the design base frame from ``q_near``
        ((6,) or (m, 6), rad; None: q^s).

        Batched: one kernel call (threads for large batches:
        :func:`~pipeline.kinematics.ik_compiled.run_in_shares`); every target
        is solved alone by the arithmetic of :meth:`solve_one`, so a batch
        equals a loop bit for bit. One target takes :meth:`solve_one`'s kernel
        call with buffers of its own (the result's arrays are the only allocations;
        :attr:`q` and the other real-time buffers are left alone). Joints
        are shifted into the limits by ±2π where that helps, as :meth:`solve_one`
        and :meth:`pipeline.control.Controller.solve` do.
        """
        Tb = np.ascontiguousarray(T_base, float)
        m, n = len(Tb), 6  # six joints (checked at construction)
        if m == 1:
            one = self._q_ref if q_near is None else np.ascontiguousarray(q_near, float).reshape(n)
            S, info, q_one, errors_one = self._one
            _solve_packed(self._packed, self._prismatic, S, info, Tb[0], one)
            kind, count = info.tolist()
            if kind == FAST_CONVERGED or kind == OFF_BRANCH:
                # The result's arrays copied from small templates: ~0.2 µs each, where
                # np.ones(1, bool) or a comparison ufunc take ~1 µs.
                errors = errors_one.copy()
                return ik.IKResult.of_one_target(
                    q=q_one.copy(), converged=_ONE_TRUE.copy(),
                    iterations=np.array([count]), position_error_cm=errors[:1],
                    orientation_error_rad=errors[1:], status=_ONE_ZERO.copy(),
                    branch_changed=(_ONE_FALSE if kind == FAST_CONVERGED else _ONE_TRUE).copy(),
                )  # fmt: skip
        near = np.ascontiguousarray(
            np.broadcast_to(self._q_ref if q_near is None else q_near, (m, n)), float
        )
        q0, q, delta, T = np.empty((m, n)), np.empty((m, n)), np.empty((m, 6)), np.empty_like(Tb)
        outcome, iterations = np.empty(m, np.int64), np.empty(m, np.int64)
        errors = np.empty((m, 2))

        def run(rows: slice) -> None:
            *model, X, lower, upper, turn = _own((*self._model, self._X, *self._limits))
            _solve_targets(*model, X, Tb[rows], near[rows], q0[rows], q[rows], delta[rows],
                           T[rows], outcome[rows], iterations[rows], errors[rows], lower,
                           upper, turn)  # type: ignore[call-arg]  # fmt: skip

        run_in_shares(run, m)
        return self.finish(T, near, q0, q, outcome, iterations, delta, errors)

    def solve_jacobi(self, T_base: Array, q_near: Array | None = None) -> ik.IKResult:
        """The Jacobi iteration (5.8) of targets (m, 4, 4) in the design base frame from
        the design start near ``q_near`` ((6,) or (m, 6), rad; None: q^s)
        (:meth:`solve`'s arguments).

        Compiled while the map contracts (:func:`_jacobi_one`); the targets it
        defers run :func:`pipeline.kinematics.ik.jacobi_iterative` (Anderson
        acceleration) from their start. Batch equals loop bit for bit.
        """
        if self.design is None or self._design is None:
            raise ValueError("PumaSolver made without the design chain: no Jacobi iteration")
        design = self._design
        Tb = np.ascontiguousarray(T_base, float)
        m, n = len(Tb), self.chain.n_joints
        near = np.ascontiguousarray(
            np.broadcast_to(self._q_ref if q_near is None else q_near, (m, n)), float
        )
        q0, q, delta, T = np.empty((m, n)), np.empty((m, n)), np.empty((m, 6)), np.empty_like(Tb)
        outcome, iterations = np.empty(m, np.int64), np.empty(m, np.int64)

        def run(rows: slice) -> None:
            *model, X = _own((*self._model, *design, self._X))
            _jacobi_targets(*model, X, Tb[rows], near[rows], q0[rows], q[rows], delta[rows],
                            T[rows], outcome[rows], iterations[rows])  # type: ignore[call-arg]  # fmt: skip

        run_in_shares(run, m)
        lost = np.flatnonzero(outcome == NO_START)
        status = np.full(m, ik.STATUS_CONVERGED, np.int64)
        status[(outcome == J_STALLED) | (outcome == J_NO_INVERSE)] = ik.STATUS_UNREACHABLE
        status[outcome == J_MAX_ITER] = ik.STATUS_MAX_ITER
        if lost.size:  # no design start: the numpy iteration from near reports them
            rest = ik.jacobi_iterative(
                self.chain, self.design, self._numpy_inverse(), T[lost], near[lost],
                self.resolution, self.settings[0], position_tol_cm=self.settings[1],
                orientation_tol_rad=self.settings[2],
            )  # fmt: skip
            q[lost], iterations[lost], status[lost] = rest.q, rest.iterations, rest.status
            delta[lost] = differential_motion(forward_kinematics(self.chain, rest.q), T[lost])
        ik.mark_singular(self.chain, q, status)
        return ik._result(q, status, iterations, ik._errors(delta))

    def _numpy_inverse(self) -> ik.DesignInverse:
        """The numpy design inverse of the Jacobi iteration (same branch and margins)."""
        from pipeline.control.puma560_inverse import puma_design_inverse

        assert self._design is not None
        margins = self._design[4]
        return puma_design_inverse(
            self.branch, tool=self._frames[1], base=self._frames[0],
            elbow_margin_rad=float(margins[0]), shoulder_margin_cm=float(margins[1]),
        )  # fmt: skip

    def finish(
        self, T: Array, near: Array, q0: Array, q: Array, outcome: IntArray,
        iterations: IntArray, delta: Array, errors: Array,
    ) -> ik.IKResult:  # fmt: skip
        """The result of kernel outputs (``errors`` (m, 2): the kernel's position and
        rotation errors): deferred targets by the numpy iteration from their start,
        targets without a start from ``near`` (the numpy design inverse's fallback),
        so the numpy iteration reports them; those rows shifted into the limits
        (the kernel shifts the rows it solves). Converged solutions off the
        requested branch are flagged (:attr:`~pipeline.kinematics.ik.IKResult.branch_changed`)."""
        status = np.zeros(len(q), np.int64)
        changed = outcome == OFF_BRANCH
        rows = np.flatnonzero((outcome != FAST_CONVERGED) & ~changed)
        if rows.size:
            start = np.where((outcome[rows] == NO_START)[:, None], near[rows], q0[rows])
            max_iter, tol_p, tol_o, max_step = self.settings
            res = ik.finish_deferred(
                self.chain, T[rows], start, self.resolution, q[rows],
                np.full(rows.size, FAST_DEFERRED), iterations[rows], delta[rows],
                max_iter=max_iter, position_tol_cm=tol_p, orientation_tol_rad=tol_o,
                max_step=max_step,
            )  # fmt: skip
            b = self.branch
            off = np.any(puma560.branch_of(res.q) != [b.shoulder, b.elbow, b.wrist], axis=-1)
            _shift(res.q, self._limits)
            q[rows], iterations[rows], status[rows] = res.q, res.iterations, res.status
            errors[rows, 0], errors[rows, 1] = res.position_error_cm, res.orientation_error_rad
            changed[rows] = res.converged & off
        return ik.IKResult(
            q=q, converged=status == ik.STATUS_CONVERGED, iterations=iterations,
            position_error_cm=errors[:, 0], orientation_error_rad=errors[:, 1], status=status,
            branch_changed=changed,
        )  # fmt: skip


def _own(arrays: tuple[Array, ...]) -> tuple[Array, ...]:
    """Copies of the model's arrays for one share of a batch (one thread): a compiled
    call increments and decrements the reference count of each array it is passed
    and of each view it makes, atomically; on arrays shared by two threads these
    counts bounce between the cores. Measured on robot3 (100,000 targets, two
    threads, best of 5): Newton-Raphson 447,000 -> 486,000 targets/s, Jacobi unchanged."""
    return tuple(a.copy() for a in arrays)


def _shift(q: Array, limits: tuple[Array, ...]) -> None:
    for row in q:
        _into_limits(row, *limits)
