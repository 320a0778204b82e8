"""The Jacobi iteration (5.8) of a Puma 560 signature, compiled: one kernel per
target runs the design start and the iteration with Anderson acceleration
(:func:`pipeline.kinematics.ik.jacobi.jacobi_iterative`, ``accelerate=True``),
while the map contracts; :class:`pipeline.control.puma560_solver.PumaSolver`
finishes the targets it defers with the numpy iteration."""

from __future__ import annotations

import numpy as np

from pipeline.control.puma560_start import NO_START, _design_start, _to_sensor
from pipeline.kinematics.ik.jacobi import ANDERSON_RCOND, JACOBI_SLOW_RATIO, JACOBI_STALL_PATIENCE
from pipeline.kinematics.ik_compiled import (
    FAST_CONVERGED,
    Buf,
    _delta,
    _errors,
    jit,
    jit_views,
    pose,
)
from pipeline.kinematics.ik_stall import STALL_RATIO

#: Jacobi kernel outcomes besides converged: stalled (no progress in
#: :data:`~pipeline.kinematics.ik.jacobi.JACOBI_STALL_PATIENCE` iterations), no design
#: inverse (both ``STATUS_UNREACHABLE``), and the iteration cap.
J_STALLED, J_NO_INVERSE, J_MAX_ITER = 4, 5, 6
_JACOBI_SLOW = JACOBI_SLOW_RATIO
_JACOBI_PATIENCE = JACOBI_STALL_PATIENCE
_ANDERSON_RCOND = ANDERSON_RCOND
_STALL = STALL_RATIO
#: :func:`_jacobi_work`: scratch of one Jacobi solve (4 history, 6 pose, 5 vector buffers,
#: the joints' cosines and sines).
JacobiWork = tuple[Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf, Buf]


@jit
def _anderson(Qh: Buf, Gh: Buf, count: int, out: Buf, dF: Buf, dG: Buf, f: Buf) -> None:
    """:func:`pipeline.kinematics.ik.jacobi._anderson` of one target: ``Qh``, ``Gh`` (h, n)
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


@jit_views
def _jacobi_map(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    d_base: Buf, d_links: Buf, d_tool: Buf, d_offsets: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf,
    target: Buf, q: Buf, Ts: Buf, q_next: Buf, Tw: Buf, Td: Buf, Delta: Buf, Tk: Buf,
    trig: Buf,
) -> bool:  # fmt: skip
    """(5.8): ``q_next = F_d⁻¹[F_d(q) · F_s(q)⁻¹ · T*]`` (``Ts``: F_s(q)); False when
    the design inverse has none. ``Tw``, ``Td``, ``Delta``, ``Tk`` (4, 4), ``trig``
    (2, n): scratch."""
    pose(d_base, d_links, d_tool, d_offsets, prismatic, q, Td, trig)
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


@jit_views
def _error_at(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    target: Buf, q: Buf, Ts: Buf, d: Buf, length: float, trig: Buf,
) -> tuple[float, float, float]:  # fmt: skip
    """F_s(q) into ``Ts``, its δ into ``d``; the position and rotation errors and the
    scaled error (``trig`` (2, n): scratch)."""
    pose(base, links, tool, offsets, prismatic, q, Ts, trig)
    _delta(Ts, target, d)
    ep, eo = _errors(d)
    return ep, eo, ep * (1.0 / length) + eo


@jit
def _jacobi_work(n: int) -> JacobiWork:
    """Scratch of :func:`_jacobi_one` for ``n`` joints, made once per batch: the
    Anderson history Qh, Gh (n + 1, n) and its differences dF (n, n), dG (n, n);
    six (4, 4) poses; q_next, q_acc (n,), δ_new, δ_acc (6,), f (n,); trig (2, n)."""
    h = n + 1
    return (
        np.zeros((h, n)), np.zeros((h, n)), np.zeros((n, h - 1)), np.zeros((h - 1, n)),
        np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)),
        np.empty((4, 4)), np.empty((4, 4)), np.empty(n), np.empty(n), np.empty(6),
        np.empty(6), np.empty(n), np.empty((2, n)),
    )  # fmt: skip


@jit
def _jacobi_one(
    base: Buf, links: Buf, tool: Buf, offsets: Buf, prismatic: Buf,
    d_base: Buf, d_links: Buf, d_tool: Buf, d_offsets: Buf,
    pre: Buf, post: Buf, branch: Buf, margins: Buf, res: Buf, settings: Buf,
    target: Buf, q: Buf, delta: Buf, Tw: Buf, work: JacobiWork,
) -> tuple[int, int]:  # fmt: skip
    """:func:`pipeline.kinematics.ik.jacobi.jacobi_iterative` (``accelerate=True``) of one
    target from ``q`` (6,) (in: the start, out: the last iterate): (5.8) with the
    design inverse on ``branch`` nearest the iterate (``margins``: the Jacobi
    clamp margins); where an iterate's error falls by less than half, Anderson
    acceleration of the same map whenever it gives the smaller error; the
    encoder rule and the pose tolerances to stop; no progress in
    :data:`~pipeline.kinematics.ik.jacobi.JACOBI_STALL_PATIENCE` iterations of
    accelerated steps, a stall. Returns the outcome and the iteration count; ``Tw``,
    ``work`` (:func:`_jacobi_work`): scratch."""
    n = q.shape[0]
    max_iter, length = int(settings[0]), settings[1]
    tol_p, tol_o = settings[2], settings[3]
    h = n + 1
    Qh, Gh, dF, dG, Ts, T_plain, T_acc, Td, Delta, Tk, q_next, q_acc, d_new, d_acc, f, cs = work
    Qh[:] = 0.0
    Gh[:] = 0.0
    ep, eo, e = _error_at(base, links, tool, offsets, prismatic, target, q, Ts, delta, length,
                          cs)  # fmt: skip
    count, slow, idle = 0, False, 0
    for it in range(1, max_iter + 1):
        found = _jacobi_map(
            base, links, tool, offsets, prismatic, d_base, d_links, d_tool, d_offsets,
            pre, post, branch, margins, target, q, Ts, q_next, Tw, Td, Delta, Tk, cs,
        )  # fmt: skip
        if not found:
            return J_NO_INVERSE, it - 1
        ep, eo, e_plain = _error_at(
            base, links, tool, offsets, prismatic, target, q_next, T_plain, d_new, length, cs
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
                base, links, tool, offsets, prismatic, target, q_acc, T_acc, d_acc, length, cs
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
    (m, 4, 4) (design base frame); outputs by row as :func:`.puma560_newton._solve_targets`."""
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
