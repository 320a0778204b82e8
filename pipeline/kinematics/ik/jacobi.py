"""The Jacobi iteration (5.8), Appendix C.2: the design model's closed-form inverse
moved by the signature's error, with Anderson acceleration where the map stops
contracting."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.ik.batch import (
    BoolArray,
    IntArray,
    _errors,
    _prepare,
    _scaled_error,
    _take,
)
from pipeline.kinematics.ik.iterate import _iterate
from pipeline.kinematics.ik.result import IKResult
from pipeline.kinematics.transforms import Array, ArrayLike, differential_motion, invert_transform

#: Design inverse for the Jacobi method: ``(T (k, 4, 4), q_near (k, n)) -> q (k, n)``.
#: Rows the design model cannot reach on the branch are NaN.
DesignInverse = Callable[[Array, Array], Array]


#: Plain Jacobi (5.8) converges linearly with a rate set by the design/signature
#: mismatch, ~1e-2 per iteration for realistic signatures (Table 5-2). An
#: iterate whose scaled error is above half the previous one marks a target on
#: which the map barely contracts or expands: next to a singularity the design
#: inverse amplifies the mismatch in one direction. Such targets are accelerated.
JACOBI_SLOW_RATIO = 0.5

#: Accelerated Jacobi iterates next to a singularity progress irregularly (the
#: design inverse is not smooth there): a step with no progress is often followed
#: by a large gain. A target is declared stalled only after this many
#: consecutive iterations without progress (Newton-Raphson: after one).
JACOBI_STALL_PATIENCE = 5

#: Relative cut-off of the Anderson least-squares problem: history differences
#: shrink geometrically, so directions below 1e-10 of the largest carry only
#: round-off of the joint coordinates (~1e-16 rad) and are dropped.
ANDERSON_RCOND = 1e-10


def _anderson(Q: Array, G: Array, count: IntArray) -> Array:
    """Anderson-accelerated fixed-point step from a history of the Jacobi map.

    With ``f_j = G(q_j) − q_j`` over the stored iterates, find ``γ`` minimising
    ``|f_k − ΔF γ|`` (``ΔF``, ``ΔG``: consecutive differences of ``f`` and ``G``)
    and return ``G(q_k) − ΔG γ``. For an affine map with ``p`` stored
    differences spanning the error this is the exact fixed point; near a
    singularity it takes the secant information that the plain iteration
    throws away. It uses only evaluations of (5.8).

    Parameters
    ----------
    Q, G : ndarray, shape (k, h, n)
        Iterates and their images, oldest first; the last ``count`` rows are valid.
    count : ndarray of int, shape (k,)

    Returns
    -------
    q_next : ndarray, shape (k, n)
    """
    F = G - Q
    dF = np.diff(F, axis=1)  # (k, h - 1, n)
    dG = np.diff(G, axis=1)
    h = Q.shape[1]
    valid = np.arange(h - 1)[None, :] >= (h - np.minimum(count, h))[:, None]
    dF = dF * valid[..., None]
    dG = dG * valid[..., None]
    gamma = np.linalg.pinv(np.swapaxes(dF, 1, 2), rcond=ANDERSON_RCOND) @ F[:, -1, :, None]
    out: Array = G[:, -1] - np.einsum("kjn,kj->kn", dG, gamma[..., 0])
    return out


def jacobi_iterative(
    signature_chain: SerialChain,
    design_chain: SerialChain,
    design_inverse: DesignInverse,
    T_target: ArrayLike,
    q0: ArrayLike,
    resolution: ArrayLike,
    max_iter: int = 50,
    *,
    position_tol_cm: float | None = 1e-7,
    orientation_tol_rad: float | None = 1e-10,
    record_history: bool = False,
    accelerate: bool = True,
) -> IKResult:
    """Invert a signature model by the Jacobi iteration (5.8), Appendix C.2.

    ``q^{k+1} = F_d⁻¹[F_d(q^k) · F_s(q^k)⁻¹ · T*]``: the design pose is moved by
    the signature model's error ``Δ^k = F_s(q^k)⁻¹ T*`` (5.9)-(5.10) and mapped
    back through the design model's closed-form inverse. Convergence is linear,
    with a rate set by the design/signature mismatch (5.12) amplified by the
    design inverse's sensitivity: next to a singularity (Puma: wrist within ~1°,
    elbow within ~1° of stretched, wrist centre within ~1 cm of the shoulder
    axis) the plain map stops contracting (measured: 0.5-1 % of targets uniform
    in the joint limits fail with ``accelerate=False``; none farther away).
    Anderson acceleration of the same map (``accelerate=True``) brings the
    failures on robot3's signature to 0.02-0.03 % of 10,000 targets.

    Parameters
    ----------
    signature_chain : SerialChain
        ``F_s``, unbatched or with a batch of ``m`` robots.
    design_chain : SerialChain
        ``F_d``, in the same world frame as ``F_s`` (Section 5.3).
    design_inverse : callable
        ``(T (k, 4, 4), q_near (k, n)) -> q (k, n)``: closed-form inverse of the
        design model on the desired branch, returning the solution nearest to
        ``q_near`` (the previous iterate) and NaN rows where the design model
        cannot reach ``T``. See :func:`~pipeline.control.puma560_inverse.puma_design_inverse`.
    T_target : array_like, shape (m, 4, 4) or (4, 4)
        Desired tool poses ``T*``, cm.
    q0 : array_like, shape (m, n) or (n,)
        Initial estimates, normally ``F_d⁻¹(T*)`` on the desired branch. Finite.
    resolution : array_like, shape (n,) or scalar
        Encoder resolution (rad / cm).
    max_iter : int
        Iteration cap per target. Realistic Puma signatures need 4-6 iterations,
        at most 11 away from singularities.
    position_tol_cm, orientation_tol_rad : float or None
        As for :func:`.newton.newton_raphson`.
    record_history : bool
        Keep the per-iteration :class:`.result.IKHistory`.
    accelerate : bool
        Where the plain iteration stops contracting (the scaled error of an
        iterate above :data:`JACOBI_SLOW_RATIO` times the previous one), later
        iterations use Anderson acceleration of the same map (:func:`_anderson`)
        whenever that gives a smaller error than (5.8) itself. Targets on which
        (5.8) contracts normally (all realistic targets away from
        singularities) iterate exactly (5.8). ``False``: the dissertation's
        iteration only.

    Returns
    -------
    IKResult
        ``STATUS_UNREACHABLE`` where ``F_d⁻¹`` found no solution; ``q`` is then
        the last iterate that had one.
    """
    T, q, res = _prepare(signature_chain, T_target, q0, resolution)
    m = T.shape[0]
    n = signature_chain.n_joints
    if design_chain.n_joints != n:
        raise KinematicsError(
            "design and signature chains differ in joint count",
            expected=str(n),
            got=str(design_chain.n_joints),
        )

    depth = n if accelerate else 0
    Q_hist = np.zeros((m, depth + 1, n))  # last iterates q^k ...
    G_hist = np.zeros((m, depth + 1, n))  # ... and their images G(q^k) under (5.8)
    count = np.zeros(m, np.int64)
    slow = np.zeros(m, bool)  # plain (5.8) stopped contracting: accelerate

    length = signature_chain.length_scale

    def step(
        rows: IntArray, q_rows: Array, delta_rows: Array, e_rows: Array
    ) -> tuple[Array, BoolArray, Array, Array, Array, BoolArray]:
        sig = _take(signature_chain, rows, m)
        F_s = forward_kinematics(sig, q_rows)  # C.2 step 2
        F_d = forward_kinematics(_take(design_chain, rows, m), q_rows)  # C.2 step 3
        T_rows = T if rows.size == m else T[rows]
        Delta = invert_transform(F_s) @ T_rows  # Eq. (5.9), C.2 step 4
        T_k = F_d @ Delta  # Eq. (5.10), C.2 step 5
        q_next = np.asarray(design_inverse(T_k, q_rows), float)  # Eq. (5.8), C.2 step 6
        if q_next.shape != q_rows.shape:
            raise KinematicsError(
                "design_inverse returned the wrong shape",
                expected=f"{q_rows.shape}",
                got=f"{q_next.shape}",
            )
        ok = np.isfinite(q_next).all(axis=-1)
        q_next = np.where(ok[:, None], q_next, q_rows)
        d_next = differential_motion(forward_kinematics(sig, q_next), T_rows)
        err_next = _errors(d_next)
        was_slow = slow[rows]
        if depth:
            e_next = _scaled_error(err_next, length)
            Q_hist[rows] = np.roll(Q_hist[rows], -1, axis=1)
            G_hist[rows] = np.roll(G_hist[rows], -1, axis=1)
            Q_hist[rows, -1], G_hist[rows, -1] = q_rows, q_next
            count[rows] += 1
            acc = np.flatnonzero(was_slow & ok)
            if acc.size:
                r = rows[acc]
                q_acc = _anderson(Q_hist[r], G_hist[r], count[r])
                d_acc = differential_motion(
                    forward_kinematics(_take(sig, acc, rows.size), q_acc), T[r]
                )
                err_acc = _errors(d_acc)
                take = _scaled_error(err_acc, length) < e_next[acc]  # never worse than (5.8)
                q_next[acc[take]] = q_acc[take]
                d_next[acc[take]] = d_acc[take]
                err_next[acc[take]] = err_acc[take]
            slow[rows] |= e_next > JACOBI_SLOW_RATIO * e_rows
        return q_next, ok, q_next - q_rows, d_next, err_next, was_slow | (depth == 0)

    return _iterate(
        signature_chain,
        T,
        q,
        differential_motion(forward_kinematics(signature_chain, q), T),
        res,
        max_iter,
        step,
        position_tol_cm,
        orientation_tol_rad,
        record_history,
        length,
        stall_patience=JACOBI_STALL_PATIENCE,
    )
