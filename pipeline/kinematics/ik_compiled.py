"""Compiled Newton-Raphson iteration (5.4), then Levenberg-Marquardt steps, for one
robot: the fast path of :func:`pipeline.kinematics.ik.newton_raphson`.

Why compiled: a numpy solve of one target costs ~500 small numpy calls of
0.5-1 µs each (four pose-and-Jacobian evaluations, three 6×6 solves and the
per-iteration bookkeeping), ~430 µs measured; the same arithmetic as scalar
loops takes a few µs. The kernel is compiled once by numba and cached on disk
in a folder named for a digest of every source the kernels are compiled from
(:mod:`pipeline.kinematics.kernel_cache`; by default in this package's
``__pycache__``), so a change to any of them compiles afresh.

What it does: for each target independently, the plain Newton iteration of
:func:`~pipeline.kinematics.ik.newton_raphson`: the Newton step ``J⁻¹ δ`` (LU
with partial pivoting), capped per joint, while it reduces the scaled error
``|dp|/L + |rotation|``, the target stopping by the module's stopping rule
(encoder rule and pose-error tolerances). Where the Newton step does not
descend, the Jacobian is singular, the target stalls or the iteration cap is
reached, the kernel goes on with Levenberg-Marquardt steps from that iterate
(:func:`_levenberg_marquardt`). Only a target on which those find no step that
lowers the error is *deferred*: the numpy iteration solves it from its start and
gives its status. A target's result never depends on the other targets in the
call (each is solved alone, serially or on one of a few threads), so a batch
equals a loop of single solves bit for bit.

The pose and Jacobian are those of
:func:`pipeline.kinematics.jacobian.pose_and_jacobian` and δ that of
:func:`pipeline.kinematics.transforms.differential_motion`, evaluated in
another order: they agree to round-off (tested against both).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar, cast

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.ik_stall import STALL_RATIO
from pipeline.kinematics.kernels import Kernel
from pipeline.kinematics.transforms import Array

#: Kernel outcome of a target: converged by the stopping rule.
FAST_CONVERGED = 0
#: Kernel outcome of a target: no step lowers its error; left to the numpy iteration.
FAST_DEFERRED = 1

#: Targets per call above which the kernel runs in one Python thread per core
#: (it releases the GIL). Below it starting the threads (~100 µs) outweighs the
#: work (~3.5 µs per target). Plain threads, not numba's ``parallel=True``: its
#: default OpenMP layer does not survive the ``fork`` of the Monte-Carlo worker
#: pool, and its fork-safe layer must not be entered from two threads at once.
THREADED_MIN_TARGETS = 2000

#: Levenberg-Marquardt: the first damping μ as a fraction of the largest diagonal
#: entry of the unit-scaled ``JᵀJ``. 1e-3 is Nielsen's choice for a start near
#: the solution (the Newton iterate it takes over from).
LM_TAU = 1e-3
#: Levenberg-Marquardt steps per target after the Newton steps. Measured on
#: robot3: the targets that need them take 5-60 (see bench/ik.py).
LM_MAX_ITER = 200
#: μ (relative to the largest diagonal entry at the LM start) above which no
#: step lowers the cost: the step is ~1e-16 of the gradient step, round-off.
LM_MU_MAX = 1e16
#: Joint step (rad) up to which a Newton trial pose takes its joints' cosines and sines
#: from those of the iterate turned by the step (:func:`_turned_trig`) instead of libm's
#: (issue 45). The step's own sine and cosine are then their Taylor series to the 8th
#: power, whose first term left out is below 1e-19 of them up to this step.
TRIG_STEP_MAX = 2.0**-6
# The series' coefficients: sin h = h (1 + t (S3 + t (S5 + t S7))), cos h = 1 + t (C2 +
# t (C4 + t (C6 + t C8))), t = h².
_S3, _S5, _S7 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0
_C2, _C4, _C6, _C8 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0
#: ``|tan θ|`` up to which δ's rotation angle ``θ = atan2(2 sin θ, 2 cos θ)``
#: (:func:`_delta`) is the series of ``atan z``, ``z = tan θ``, to ``z⁹``, not libm's
#: ``atan2`` (issue 45: a Newton iterate's rotation error is ~1e-3 rad and less); the
#: first term left out is below 1e-19 of it.
ATAN_SERIES_MAX = 2.0**-6
_A3, _A5, _A7, _A9 = -1.0 / 3.0, 1.0 / 5.0, -1.0 / 7.0, 1.0 / 9.0


Func = TypeVar("Func", bound=Callable[..., Any])
IntArray = npt.NDArray[np.int64]
#: Argument type of the compiled kernels: float, bool or int buffers.
Buf = npt.NDArray[Any]
#: :func:`workspace`: scratch buffers of one solve.
Work = tuple[Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf]


def jit(func: Func) -> Func:
    """Compile ``func`` with numba (no Python objects, GIL released, cached on disk in
    :func:`~pipeline.kinematics.kernel_cache.cache_dir`) on its first compiled call
    (:class:`~pipeline.kinematics.kernels.Kernel`). No kernel is inlined at numba's
    level (``inline="always"``, issue 45): it retyped a callee at every call site, and the
    kernels took 86 s of CPU to compile instead of 38 s, for 12-25 % of a batch's speed
    (measured 2026-11-29 on robot3's signature, CPU per target, same run: Newton-Raphson
    batch 6.3 against 7.2 µs, Jacobi 6.8 against 9.1 µs, one real-time target 14.4
    against 14.8 µs; docs/scale.md). LLVM still inlines small callees."""
    return cast(Func, Kernel(func, {"nogil": True}))


def jit_views(func: Func) -> Func:
    """:func:`jit` for a kernel that allocates nothing (it reads and writes the buffers
    it is given, and views of them), compiled without numba's reference counting; it may
    call only such kernels (numba types a callee in its caller's mode). Measured (perf,
    robot3, 100,000 targets of one branch on one thread, issue 45): the counting's atomic
    increments and decrements of every array argument and view, at every call between
    kernels, took 30 % of the samples, 2.8× the time in sin and cos; with the Newton and
    Levenberg-Marquardt kernels (their scratch in :func:`workspace`) and the Puma's
    compiled this way, 2.5 µs of CPU per target instead of 3.6. The arithmetic, hence
    every answer, is the same."""
    return cast(Func, Kernel(func, {"nogil": True, "_nrt": False}))


@jit_views
def _pose_into(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    q: Buf, T: Buf, J: Buf, trig: Buf, jacobian: bool,
) -> None:  # fmt: skip
    """Tool pose ``T`` (4, 4) at ``q`` (n,) and, when ``jacobian``, the geometric
    Jacobian ``J`` (6, n); the running frame in scalars, nothing allocated. ``trig``
    (2, n): the revolute joints' ``cos`` and ``sin`` of ``q_i − q0_i``, given
    (:func:`_joint_trig`, :func:`_turned_trig`); it may be ``J`` (column ``i`` is read
    before joint ``i``'s axis and origin are written there).

    The cosines and sines come in computed, not computed between the frame products
    (issue 45): a call of libm's ``sincos`` between two joints' products made the compiler
    keep the running frame (12 scalars) in memory around it (the call may overwrite every
    floating-point register). Measured on robot3's chain, one pose and Jacobian 117 ns
    instead of 168 ns, the same bits.

    Eq. (5.1): ``T = base · Π Rot(z, q_i − q0_i) · K̄_i · tool`` (Eq. (5.2); a
    prismatic joint ``Trans(0, 0, q_i − q0_i)``, Eq. (5.3)), the transforms'
    last rows exactly ``0 0 0 1`` (:func:`homogeneous`), so their products with
    it are left out: the same value as the full product, bit for bit. Column ``i`` of J
    is ``[z_i × (p_tool − p_i); z_i]`` (revolute) or ``[z_i; 0]`` (prismatic),
    ``z_i``, ``p_i`` joint ``i``'s axis and origin (kept in J until the tool's
    origin is known).
    """
    n = q.shape[0]
    f00, f01, f02, f03 = base[0, 0], base[0, 1], base[0, 2], base[0, 3]
    f10, f11, f12, f13 = base[1, 0], base[1, 1], base[1, 2], base[1, 3]
    f20, f21, f22, f23 = base[2, 0], base[2, 1], base[2, 2], base[2, 3]
    for i in range(n):
        co, si = trig[0, i], trig[1, i]  # (read before J's column i is written)
        if jacobian:
            J[0, i], J[1, i], J[2, i] = f03, f13, f23  # p_i
            J[3, i], J[4, i], J[5, i] = f02, f12, f22  # z_i
        if prismatic[i]:  # Eq. (5.3)
            d = q[i] - offsets[i]
            f03 += d * f02
            f13 += d * f12
            f23 += d * f22
        else:  # Eq. (5.2)
            f00, f01 = co * f00 + si * f01, co * f01 - si * f00
            f10, f11 = co * f10 + si * f11, co * f11 - si * f10
            f20, f21 = co * f20 + si * f21, co * f21 - si * f20
        L = links[i]  # Eq. (5.1): F ← F · K̄_i (K̄_i's last row 0 0 0 1: homogeneous)
        l00, l01, l02, l03 = L[0, 0], L[0, 1], L[0, 2], L[0, 3]
        l10, l11, l12, l13 = L[1, 0], L[1, 1], L[1, 2], L[1, 3]
        l20, l21, l22, l23 = L[2, 0], L[2, 1], L[2, 2], L[2, 3]
        f00, f01, f02, f03 = (f00 * l00 + f01 * l10 + f02 * l20,
                              f00 * l01 + f01 * l11 + f02 * l21,
                              f00 * l02 + f01 * l12 + f02 * l22,
                              f00 * l03 + f01 * l13 + f02 * l23 + f03)  # fmt: skip
        f10, f11, f12, f13 = (f10 * l00 + f11 * l10 + f12 * l20,
                              f10 * l01 + f11 * l11 + f12 * l21,
                              f10 * l02 + f11 * l12 + f12 * l22,
                              f10 * l03 + f11 * l13 + f12 * l23 + f13)  # fmt: skip
        f20, f21, f22, f23 = (f20 * l00 + f21 * l10 + f22 * l20,
                              f20 * l01 + f21 * l11 + f22 * l21,
                              f20 * l02 + f21 * l12 + f22 * l22,
                              f20 * l03 + f21 * l13 + f22 * l23 + f23)  # fmt: skip
    for c in range(3):
        t0, t1, t2 = tool[0, c], tool[1, c], tool[2, c]
        T[0, c] = f00 * t0 + f01 * t1 + f02 * t2
        T[1, c] = f10 * t0 + f11 * t1 + f12 * t2
        T[2, c] = f20 * t0 + f21 * t1 + f22 * t2
    t0, t1, t2 = tool[0, 3], tool[1, 3], tool[2, 3]
    T[0, 3] = f00 * t0 + f01 * t1 + f02 * t2 + f03
    T[1, 3] = f10 * t0 + f11 * t1 + f12 * t2 + f13
    T[2, 3] = f20 * t0 + f21 * t1 + f22 * t2 + f23
    T[3, 0], T[3, 1], T[3, 2], T[3, 3] = 0.0, 0.0, 0.0, 1.0
    if not jacobian:
        return
    px, py, pz = T[0, 3], T[1, 3], T[2, 3]
    for i in range(n):
        zx, zy, zz = J[3, i], J[4, i], J[5, i]
        if prismatic[i]:
            J[0, i], J[1, i], J[2, i] = zx, zy, zz
            J[3, i], J[4, i], J[5, i] = 0.0, 0.0, 0.0
        else:
            rx, ry, rz = px - J[0, i], py - J[1, i], pz - J[2, i]
            J[0, i] = zy * rz - zz * ry
            J[1, i] = zz * rx - zx * rz
            J[2, i] = zx * ry - zy * rx


def homogeneous(base: Array, links: Array, tool: Array) -> bool:
    """Whether every transform of a chain has the last row ``0 0 0 1`` exactly, as
    :func:`_pose_into` assumes."""
    last = np.array([0.0, 0.0, 0.0, 1.0])
    return bool(np.all(base[..., 3, :] == last) and np.all(links[..., 3, :] == last)
                and np.all(tool[..., 3, :] == last))  # fmt: skip


@jit_views
def pose(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf, q: Buf, T: Buf, trig: Buf
) -> None:  # fmt: skip
    """Tool pose ``T`` (4, 4) at ``q`` (n,) (:func:`_pose_into` without the Jacobian;
    ``trig`` (2, n): scratch)."""
    _joint_trig(q, offsets, prismatic, trig)
    _pose_into(base, links, tool, offsets, prismatic, q, T, T, trig, False)


@jit_views
def _pose_jacobian(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf, q: Buf, T: Buf, J: Buf,
) -> None:  # fmt: skip
    """Tool pose ``T`` (4, 4) and geometric Jacobian ``J`` (6, n) at ``q`` (n,)
    (:func:`_pose_into`)."""
    _joint_trig(q, offsets, prismatic, J)
    _pose_into(base, links, tool, offsets, prismatic, q, T, J, J, True)


@jit_views
def _joint_trig(q: Buf, offsets: Buf, prismatic: Buf, trig: Buf) -> None:
    """``cos`` and ``sin`` of each revolute joint's ``q_i − q0_i`` into ``trig`` (2, n)
    (libm's; prismatic joints' columns left alone)."""
    for i in range(q.shape[0]):
        if not prismatic[i]:
            d = q[i] - offsets[i]
            trig[0, i], trig[1, i] = np.cos(d), np.sin(d)


@jit_views
def _turned_trig(
    q: Buf, q_new: Buf, offsets: Buf, prismatic: Buf, trig: Buf, trig_new: Buf
) -> None:  # fmt: skip
    """``trig_new`` (2, n): the cosines and sines at ``q_new`` from ``trig``, those at
    ``q`` (n,): each joint's turned by its step ``h = q_new_i − q_i``
    (``cos(d + h) = cos d cos h − sin d sin h``, ``sin(d + h) = sin d cos h + cos d sin h``,
    ``sin h`` and ``cos h`` by their series, no libm call); libm's where ``|h|`` exceeds
    :data:`TRIG_STEP_MAX`. A Newton iterate's steps are of the model error's size
    (~1e-3 rad) and shrink quadratically, so a trial pose calls no libm function;
    the values agree with libm's to a few units in the last place (each turn adds ~1),
    the pose to ~1e-15: 1e-5 of the stopping rule's orientation tolerance (1e-10 rad)."""
    for i in range(q.shape[0]):
        if prismatic[i]:
            continue
        h = q_new[i] - q[i]
        if abs(h) > TRIG_STEP_MAX:
            d = q_new[i] - offsets[i]
            trig_new[0, i], trig_new[1, i] = np.cos(d), np.sin(d)
            continue
        t = h * h
        sin_h = h * (1.0 + t * (_S3 + t * (_S5 + t * _S7)))
        cos_h = 1.0 + t * (_C2 + t * (_C4 + t * (_C6 + t * _C8)))
        co, si = trig[0, i], trig[1, i]
        trig_new[0, i] = co * cos_h - si * sin_h
        trig_new[1, i] = si * cos_h + co * sin_h


@jit_views
def _delta(T_from: Buf, T_to: Buf, out: Buf) -> None:
    """``differential_motion(T_from, T_to)`` into ``out`` (6,): origin difference and
    the axis-angle vector of ``R = R_to R_fromᵀ`` (its entries as scalars)."""
    a00, a01, a02 = T_to[0, 0], T_to[0, 1], T_to[0, 2]
    a10, a11, a12 = T_to[1, 0], T_to[1, 1], T_to[1, 2]
    a20, a21, a22 = T_to[2, 0], T_to[2, 1], T_to[2, 2]
    b00, b01, b02 = T_from[0, 0], T_from[0, 1], T_from[0, 2]
    b10, b11, b12 = T_from[1, 0], T_from[1, 1], T_from[1, 2]
    b20, b21, b22 = T_from[2, 0], T_from[2, 1], T_from[2, 2]
    r00 = a00 * b00 + a01 * b01 + a02 * b02  # r_ij = row i of R_to · row j of R_from
    r11 = a10 * b10 + a11 * b11 + a12 * b12
    r22 = a20 * b20 + a21 * b21 + a22 * b22
    r01 = a00 * b10 + a01 * b11 + a02 * b12
    r10 = a10 * b00 + a11 * b01 + a12 * b02
    r02 = a00 * b20 + a01 * b21 + a02 * b22
    r20 = a20 * b00 + a21 * b01 + a22 * b02
    r12 = a10 * b20 + a11 * b21 + a12 * b22
    r21 = a20 * b10 + a21 * b11 + a22 * b12
    sx, sy, sz = r21 - r12, r02 - r20, r10 - r01  # 2 sin(θ) · axis
    two_sin = np.sqrt(sx * sx + sy * sy + sz * sz)
    two_cos = r00 + r11 + r22 - 1.0
    if two_cos > 0.0 and two_sin <= ATAN_SERIES_MAX * two_cos:
        z = two_sin / two_cos
        t = z * z
        angle = z * (1.0 + t * (_A3 + t * (_A5 + t * (_A7 + t * _A9))))
    else:
        angle = np.arctan2(two_sin, two_cos)
    # θ / (2 sin θ) → 1/2 below sin θ ~ 1e-12, the round-off of R (as differential_motion).
    scale = angle / two_sin if two_sin > 2e-12 else 0.5
    for r in range(3):
        out[r] = T_to[r, 3] - T_from[r, 3]
    out[3], out[4], out[5] = sx * scale, sy * scale, sz * scale


@jit_views
def _lu_solve(A: Buf, b: Buf, x: Buf, M: Buf) -> bool:
    """``x = A⁻¹ b`` for a square ``A`` (n, n) by LU with partial pivoting (``M``: scratch
    (n, n + 1)). False when a pivot is zero or the solution is not finite.

    Six joints take :func:`_lu_solve6`: the same elimination with constant loop
    bounds, which the compiler unrolls (~160 ns instead of ~245 ns), each pivot's
    reciprocal multiplied instead of 21 divisions (issue 45: 120 → 96 ns; the solution
    to a unit in the last place of the divisions')."""
    n = A.shape[0]
    if n == 6:
        return _lu_solve6(A, b, x, M)
    for i in range(n):
        for j in range(n):
            M[i, j] = A[i, j]
        M[i, n] = b[i]
    for k in range(n):
        p = k
        for i in range(k + 1, n):
            if abs(M[i, k]) > abs(M[p, k]):
                p = i
        if M[p, k] == 0.0:
            return False
        if p != k:
            for j in range(k, n + 1):
                M[k, j], M[p, j] = M[p, j], M[k, j]
        for i in range(k + 1, n):
            f = M[i, k] / M[k, k]
            for j in range(k + 1, n + 1):
                M[i, j] -= f * M[k, j]
    for i in range(n - 1, -1, -1):
        s = M[i, n]
        for j in range(i + 1, n):
            s -= M[i, j] * x[j]
        x[i] = s / M[i, i]
        if not np.isfinite(x[i]):
            return False
    return True


@jit_views
def _lu_solve6(A: Buf, b: Buf, x: Buf, M: Buf) -> bool:
    """:func:`_lu_solve` of a (6, 6) system."""
    for i in range(6):
        for j in range(6):
            M[i, j] = A[i, j]
        M[i, 6] = b[i]
    for k in range(6):
        p, big = k, abs(M[k, k])
        for i in range(k + 1, 6):
            if abs(M[i, k]) > big:
                p, big = i, abs(M[i, k])
        if big == 0.0:
            return False
        if p != k:
            for j in range(k, 7):
                M[k, j], M[p, j] = M[p, j], M[k, j]
        M[k, k] = 1.0 / M[k, k]  # (kept for the back substitution)
        for i in range(k + 1, 6):
            f = M[i, k] * M[k, k]
            for j in range(k + 1, 7):
                M[i, j] -= f * M[k, j]
    for i in range(5, -1, -1):
        s = M[i, 6]
        for j in range(i + 1, 6):
            s -= M[i, j] * x[j]
        x[i] = s * M[i, i]
        if not np.isfinite(x[i]):
            return False
    return True


@jit_views
def _errors(d: Buf) -> tuple[float, float]:
    """Radial position error (cm) and rotation angle (rad) of δ (6,)."""
    return (
        np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]),
        np.sqrt(d[3] * d[3] + d[4] * d[4] + d[5] * d[5]),
    )


@jit
def workspace(n: int) -> Work:
    """Scratch of :func:`solve_one_target` for ``n`` joints, made once per batch (or
    per real-time solver) so that no target allocates: T (4, 4), J (6, n),
    M (n, n + 1), dq, q_new (n,), δ_new (6,), then :func:`_levenberg_marquardt`'s
    J_new (6, n), A, Am (n, n), g (n,), r (6,), Js (6, n), then the Newton iteration's
    cosines and sines (2, n) at the iterate and at the trial (:func:`_turned_trig`)."""
    return (np.empty((4, 4)), np.empty((6, n)), np.empty((n, n + 1)), np.empty(n),
            np.empty(n), np.empty(6), np.empty((6, n)), np.empty((n, n)), np.empty((n, n)),
            np.empty(n), np.empty(6), np.empty((6, n)), np.empty((2, n)),
            np.empty((2, n)))  # fmt: skip


@jit_views
def solve_one_target(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    target: Buf, q: Buf, res: Buf, limit: Buf, settings: Buf, delta: Buf, ws: Work,
) -> tuple[int, int]:  # fmt: skip
    """Newton-Raphson on one target, then Levenberg-Marquardt where it stops descending;
    ``q`` (n,) in: the start, out: the solution.

    ``settings`` = (max_iter, length scale L, position tol. cm, orientation tol. rad).
    Returns (outcome, iterations); ``delta`` (6,) receives the final δ; ``ws``:
    :func:`workspace`.

    The stopping rule is tested on the trial iterate, as the numpy iteration
    does. Testing it before the trial pose (stop at an iterate within the pose
    tolerances whose increment is below one count) was measured on robot3:
    it ends 106 of 100,000 solves one pose earlier (the pose tolerances, not
    the encoder rule, decide when the others stop), so it is not done.
    """
    n = q.shape[0]
    max_iter, length = int(settings[0]), settings[1]
    tol_p, tol_o = settings[2], settings[3]
    T, J, M, dq, q_new, d_new = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5]
    trig, trig_new = ws[12], ws[13]  # cos, sin at q and at q_new (_turned_trig)
    _joint_trig(q, offsets, prismatic, trig)
    _pose_into(base, links, tool, offsets, prismatic, q, T, J, trig, True)
    _delta(T, target, delta)  # Appendix C.1 steps 1-2 at q⁰
    ep, eo = _errors(delta)
    e = ep * (1.0 / length) + eo
    accurate_q = ep <= tol_p and eo <= tol_o  # the pose error at q
    for it in range(1, max_iter + 1):
        if not _lu_solve(J, delta, dq, M):  # Eq. (5.4): dq = J⁻¹ δ
            return _levenberg_marquardt(
                base, links, tool, offsets, prismatic, target, q, res, limit, settings,
                delta, J, it - 1, ws,
            )  # fmt: skip
        worst = 1.0  # C.1 step 7, the step capped per joint (ik.steps._cap_step)
        for j in range(n):
            if abs(dq[j]) > limit[j]:  # (a ratio up to 1 leaves worst at 1: no division)
                worst = max(worst, abs(dq[j]) / limit[j])
        small = True  # Appendix C.1 step 8: every increment below one count
        for j in range(n):
            q_new[j] = q[j] + (dq[j] / worst if worst > 1.0 else dq[j])
            small = small and abs(dq[j]) < res[j]
        # The trial pose; its Jacobian only where the solve cannot end at q_new (a
        # step below one count), else computed when it goes on (below).
        _turned_trig(q, q_new, offsets, prismatic, trig, trig_new)
        _pose_into(base, links, tool, offsets, prismatic, q_new, T, J, trig_new, not small)
        _delta(T, target, d_new)
        ep, eo = _errors(d_new)
        e_new = ep * (1.0 / length) + eo
        if not e_new < e and small and accurate_q:
            # Round-off: q is within tolerance and its Newton increment below one
            # count (an exact start); the numpy iteration stops here too (C.1 step 8).
            return FAST_CONVERGED, it
        if not e_new < e:  # the Newton step does not descend: damped steps from q
            _pose_into(base, links, tool, offsets, prismatic, q, T, J, trig, True)
            return _levenberg_marquardt(
                base, links, tool, offsets, prismatic, target, q, res, limit, settings,
                delta, J, it - 1, ws,
            )  # fmt: skip
        accurate = ep <= tol_p and eo <= tol_o
        moved = False
        for j in range(n):
            moved = moved or abs(q_new[j] - q[j]) >= res[j]
            q[j] = q_new[j]
            trig[0, j], trig[1, j] = trig_new[0, j], trig_new[1, j]
        for r in range(6):
            delta[r] = d_new[r]
        if small and accurate:
            return FAST_CONVERGED, it
        if small:  # going on: the Jacobian at q (the same pose again, with it)
            _pose_into(base, links, tool, offsets, prismatic, q, T, J, trig, True)
        accurate_q = accurate
        if not accurate and not e_new < STALL_RATIO * e and not moved:
            return _levenberg_marquardt(
                base, links, tool, offsets, prismatic, target, q, res, limit, settings,
                delta, J, it, ws,
            )  # fmt: skip
        e = e_new
    return _levenberg_marquardt(
        base,
        links,
        tool,
        offsets,
        prismatic,
        target,
        q,
        res,
        limit,
        settings,
        delta,
        J,
        max_iter,
        ws,
    )


@jit_views
def _levenberg_marquardt(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    target: Buf, q: Buf, res: Buf, limit: Buf, settings: Buf, delta: Buf, J: Buf, done: int,
    ws: Work,
) -> tuple[int, int]:  # fmt: skip
    """Damped least squares from ``q`` (δ and J given there) after ``done`` Newton steps;
    ``ws``: :func:`solve_one_target`'s :func:`workspace` (its first six buffers free once
    the Newton steps hand over, ``J`` read before any is written).

    Minimises ``½|W δ|²``, ``W = diag(1/L, 1/L, 1/L, 1, 1, 1)``, by steps
    ``h = (JᵀWᵀWJ + μ I)⁻¹ JᵀWᵀW δ`` capped per joint; μ follows Nielsen's rule
    (Madsen, Nielsen & Tingleff 2004, Algorithm 3.16): start at
    :data:`LM_TAU` × the largest diagonal entry, shrink after a step that
    lowers the cost, double (then quadruple, ...) after one that does not.
    After every step that lowers the cost the undamped (Gauss-Newton, μ = 0)
    step is tried first, so the iteration is Newton's again, quadratic, as
    soon as it descends; μ resumes where it was when it does not.
    The target converges when its pose error is within tolerance and every
    increment of the accepted step is below one encoder count (Appendix C.1
    step 8), or when it is within tolerance and no step lowers the cost any
    more (round-off). Deferred when μ grows beyond :data:`LM_MU_MAX` (a
    minimum of the residual) or after :data:`LM_MAX_ITER` steps.
    """
    n = q.shape[0]
    length = settings[1]
    tol_p, tol_o = settings[2], settings[3]
    w = 1.0 / length
    T, M, h, q_new, d_new = ws[0], ws[2], ws[3], ws[4], ws[5]
    J_new, A, Am, g, r, Js = ws[6], ws[7], ws[8], ws[9], ws[10], ws[11]

    def normal_equations(J: Buf, d: Buf) -> float:  # A = JsᵀJs, g = Jsᵀ r; returns ½|r|²
        for i in range(6):
            s = w if i < 3 else 1.0
            r[i] = s * d[i]
            for j in range(n):
                Js[i, j] = s * J[i, j]
        for a in range(n):
            acc = 0.0
            for i in range(6):
                acc += Js[i, a] * r[i]
            g[a] = acc
            for b in range(a, n):
                acc = 0.0
                for i in range(6):
                    acc += Js[i, a] * Js[i, b]
                A[a, b] = acc
                A[b, a] = acc
        return float(0.5 * (r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3]
                            + r[4] * r[4] + r[5] * r[5]))  # fmt: skip

    cost = normal_equations(J, delta)
    top = 0.0
    for a in range(n):
        top = max(top, A[a, a])
    mu, nu = LM_TAU * top, 2.0
    gauss_newton = False  # try μ = 0 first (after a step that lowered the cost)
    ep, eo = _errors(delta)
    for it in range(done + 1, done + LM_MAX_ITER + 1):
        damp = 0.0 if gauss_newton else mu
        for a in range(n):
            for b in range(n):
                Am[a, b] = A[a, b]
            Am[a, a] += damp
        if not _lu_solve(Am, g, h, M):
            if gauss_newton:
                gauss_newton = False
                continue
            return FAST_DEFERRED, it
        worst = 1.0
        for j in range(n):
            if abs(h[j]) > limit[j]:
                worst = max(worst, abs(h[j]) / limit[j])
        small = True
        for j in range(n):
            h[j] = h[j] / worst if worst > 1.0 else h[j]
            q_new[j] = q[j] + h[j]
            # the encoder rule tests an undamped increment only: a short damped
            # step says nothing about being near the solution
            small = small and damp == 0.0 and abs(h[j]) < res[j]
        _pose_jacobian(base, links, tool, offsets, prismatic, q_new, T, J_new)
        _delta(T, target, d_new)
        c_new = 0.5 * (
            (w * d_new[0]) ** 2 + (w * d_new[1]) ** 2 + (w * d_new[2]) ** 2
            + d_new[3] ** 2 + d_new[4] ** 2 + d_new[5] ** 2
        )  # fmt: skip
        if c_new < cost:
            predicted = 0.0  # ½ hᵀ(μ h + g), the model's decrease (> 0)
            for j in range(n):
                predicted += 0.5 * h[j] * (damp * h[j] + g[j])
            rho = (cost - c_new) / predicted if predicted > 0.0 else 1.0
            for j in range(n):
                q[j] = q_new[j]
            for i in range(6):
                delta[i] = d_new[i]
            ep, eo = _errors(delta)
            if small and ep <= tol_p and eo <= tol_o:
                return FAST_CONVERGED, it
            cost = normal_equations(J_new, delta)
            if not gauss_newton:
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
            gauss_newton = True
        elif gauss_newton:  # the undamped step did not descend: damp from here on
            gauss_newton = False
        else:
            # within (finite) tolerances, at round-off
            if ep <= tol_p and eo <= tol_o and tol_p < np.inf and tol_o < np.inf:
                return FAST_CONVERGED, it  # the rejected trial counts, as in numpy
            mu *= nu
            nu *= 2.0
            if not mu <= LM_MU_MAX * top:
                return FAST_DEFERRED, it
    return FAST_DEFERRED, done + LM_MAX_ITER


@jit
def _solve_serial(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    targets: Buf, q: Buf, res: Buf, limit: Buf, settings: Buf,
    outcome: Buf, iterations: Buf, delta: Buf,
) -> None:  # fmt: skip
    ws = workspace(q.shape[1])
    for k in range(targets.shape[0]):
        outcome[k], iterations[k] = solve_one_target(
            base, links, tool, offsets, prismatic, targets[k], q[k], res, limit, settings,
            delta[k], ws,
        )  # fmt: skip


def plain_newton(
    base: Array,
    links: Array,
    tool: Array,
    offsets: Array,
    prismatic: Array,
    targets: Array,
    q0: Array,
    res: Array,
    limit: Array,
    max_iter: int,
    length: float,
    position_tol_cm: float,
    orientation_tol_rad: float,
) -> tuple[Array, IntArray, IntArray, Array]:
    """Run the kernel on ``m`` targets of one robot (see the module docstring).

    Parameters
    ----------
    base, tool : ndarray, shape (4, 4)
    links : ndarray, shape (n, 4, 4)
        The chain's constant link transforms ``K̄_i``.
    offsets : ndarray, shape (n,)
        Joint offsets ``q0_i`` (rad / cm).
    prismatic : ndarray of bool, shape (n,)
    targets : ndarray, shape (m, 4, 4)
        Desired tool poses in the chain's world frame, cm.
    q0 : ndarray, shape (m, n)
        Starts (rad / cm); not modified.
    res, limit : ndarray, shape (n,)
        Encoder resolution and step cap per joint (rad / cm).
    max_iter : int
    length : float
        The chain's length scale L (cm).
    position_tol_cm, orientation_tol_rad : float
        Pose-error tolerances (``inf``: none).

    Returns
    -------
    q : ndarray, shape (m, n)
        Solutions (rows of deferred targets: meaningless).
    outcome : ndarray of int, shape (m,)
        :data:`FAST_CONVERGED` or :data:`FAST_DEFERRED`.
    iterations : ndarray of int, shape (m,)
    delta : ndarray, shape (m, 6)
        Final δ (cm, rad).
    """
    m = targets.shape[0]
    q = np.array(q0, float, order="C", copy=True)
    outcome, iterations = np.empty(m, np.int64), np.empty(m, np.int64)
    delta = np.empty((m, 6))
    settings = np.array([max_iter, length, position_tol_cm, orientation_tol_rad], float)
    model = (
        np.ascontiguousarray(base, float), np.ascontiguousarray(links, float),
        np.ascontiguousarray(tool, float), np.ascontiguousarray(offsets, float),
        np.ascontiguousarray(prismatic, np.bool_),
    )  # fmt: skip
    T = np.ascontiguousarray(targets, float)
    res_c, limit_c = np.ascontiguousarray(res, float), np.ascontiguousarray(limit, float)

    def run(rows: slice) -> None:
        _solve_serial(*model, T[rows], q[rows], res_c, limit_c, settings,
                      outcome[rows], iterations[rows], delta[rows])  # fmt: skip

    run_in_shares(run, m)
    return q, outcome, iterations, delta


def run_in_shares(run: Callable[[slice], None], m: int) -> None:
    """``run(rows)`` over ``m`` targets: one call, or for a batch of at least
    :data:`THREADED_MIN_TARGETS` one contiguous share per core on threads (the
    kernels release the GIL). Each target is still solved alone, so the split
    does not change any result."""
    # The cores are counted only for a batch that may use them (not per single target).
    workers = len(os.sched_getaffinity(0)) if m >= THREADED_MIN_TARGETS else 1
    if workers < 2:
        run(slice(0, m))
    else:
        bounds = np.linspace(0, m, workers + 1).astype(int)
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(run, [slice(a, b) for a, b in zip(bounds, bounds[1:], strict=False)]))
