"""The Puma 560 design start, compiled: the closed-form inverse of the design model
(Appendix B.2) on one branch, pulled onto the design workspace where a pose lies
outside it, and the small per-target kernels around it (the pose in the sensor
frame, the branch test, the joint-limit shift and test). Kernels of
:mod:`pipeline.control.puma560_newton` and :mod:`pipeline.control.puma560_jacobi`
call them; the design lengths are frozen into their machine code."""

from __future__ import annotations

import math

import numpy as np

from pipeline.kinematics.ik_compiled import Buf, jit_views
from pipeline.robots import puma560

#: Kernel outcome: the design inverse has no start (the clamped pose is still out
#: of reach; not met with finite poses, kept so no NaN reaches the iteration).
NO_START = 2


_D1, _D3, _, _D4, _, _D6 = puma560.DESIGN_D_CM
_A2, _A3 = puma560.DESIGN_A_CM[1], puma560.DESIGN_A_CM[2]
_RHO2 = _D4**2 + _A3**2
_PHI = math.atan2(_A3, _D4)
_TWO_PI = 2.0 * math.pi
_SINGULAR = puma560.WRIST_SINGULAR_TOL


@jit_views
def _wrap(t: float) -> float:
    """:func:`pipeline.kinematics.transforms.wrap_angle` of one angle: (-π, π]."""
    a = math.pi - t
    # np.mod(a, 2π) is a itself for 0 <= a < 2π (fmod is exact): skip its call there
    return math.pi - (a if 0.0 <= a < _TWO_PI else np.mod(a, _TWO_PI))


@jit_views
def _design_start(
    pre: Buf, post: Buf, branch: Buf, margins: Buf, target: Buf, q_near: Buf, q: Buf, Tw: Buf
) -> bool:
    """The design inverse of one target into ``q`` (6,): steps 1-2 of
    :mod:`pipeline.control.puma560_newton`'s docstring.

    ``pre``, ``post`` (4, 4): world (sensor) to D-H frame 0 and tool to flange;
    ``branch`` (3,): shoulder, elbow, wrist flags (±1); ``margins`` (2,): the clamp's
    elbow margin (rad) and shoulder margin (cm); ``Tw`` (4, 4): scratch.
    False when even the clamped pose has no solution.
    """
    # Tw = (pre · target) · post, as puma_design_inverse; its rows 0-2 (row r of the
    # product is row r of pre · target times post; the inverse reads no row 3)
    for r in range(3):
        for c in range(4):
            Tw[r, c] = (pre[r, 0] * target[0, c] + pre[r, 1] * target[1, c]
                        + pre[r, 2] * target[2, c] + pre[r, 3] * target[3, c])  # fmt: skip
    for r in range(3):
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


@jit_views
def _into_limits(q: Buf, lower: Buf, upper: Buf, turn: Buf) -> None:
    """``pipeline.control._shift_into`` of one configuration (6,), in place."""
    for j in range(q.shape[0]):
        if q[j] < lower[j] or q[j] > upper[j]:
            up, down = q[j] + turn[j], q[j] - turn[j]
            if lower[j] <= up <= upper[j]:
                q[j] = up
            elif lower[j] <= down <= upper[j]:
                q[j] = down


@jit_views
def _inside(q: Buf, lower: Buf, upper: Buf) -> bool:
    """Whether every joint of ``q`` (6,) is inside its limits."""
    for j in range(q.shape[0]):
        if q[j] < lower[j] or q[j] > upper[j]:
            return False
    return True


@jit_views
def _to_sensor(X: Buf, T_base: Buf, target: Buf) -> None:
    """``target = X · T_base`` (4, 4): a pose in the design base frame in the sensor frame."""
    for r in range(4):
        for c in range(4):
            target[r, c] = (X[r, 0] * T_base[0, c] + X[r, 1] * T_base[1, c]
                            + X[r, 2] * T_base[2, c] + X[r, 3] * T_base[3, c])  # fmt: skip


@jit_views
def _arm_flags(q: Buf) -> tuple[float, float]:
    """The shoulder and elbow flags (±1) of ``q`` (6,), as
    :func:`pipeline.robots.puma560.branch_of`."""
    s23, c23 = math.sin(q[1] + q[2]), math.cos(q[1] + q[2])
    reach = _D4 * s23 + _A3 * c23 + _A2 * math.cos(q[1])
    elbow = math.cos(q[2] + _PHI)
    return (1.0 if reach >= 0 else -1.0), (1.0 if elbow >= 0 else -1.0)


@jit_views
def _same_arm(q: Buf, other: Buf) -> bool:
    """``q`` and ``other`` (6,) have the same shoulder and elbow flags."""
    s, e = _arm_flags(q)
    s_o, e_o = _arm_flags(other)
    return s == s_o and e == e_o


@jit_views
def _on_branch(q: Buf, branch: Buf) -> bool:
    """:func:`pipeline.robots.puma560.branch_of` of ``q`` (6,) equals ``branch`` (3,)."""
    s, e = _arm_flags(q)
    w = 1.0 if math.sin(q[4]) >= 0 else -1.0
    return s == branch[0] and e == branch[1] and w == branch[2]
