"""Numerical inverse kinematics of identified models: Newton-Raphson (5.4) and Jacobi (5.8).

Signature models have no closed-form inverse (Section 5.1), so the joint
coordinates ``q*`` with ``F_s(q*) = T*`` are found iteratively, starting from the
closed-form inverse of the *design* model on the desired configuration branch
(Section 5.2; for the Puma 560 that is
:func:`pipeline.control.puma560_inverse.puma_design_inverse`). Both solvers are
batch-first: ``m`` targets of shape ``(m, 4, 4)`` and ``m`` starts of shape
``(m, n)``; a single target is a batch of one. Every target iterates and stops on
its own. Lengths are in cm, angles in radians.

Stopping rule
    Section 5.2 / Appendix C.1 step 8: a target has converged when every
    component of the method's increment is below its encoder resolution; the
    increment is still applied. That rule alone is not accurate enough for a
    1e-6 cm / 1e-7° target. Measured on 10,000 random Puma 560 targets of a
    realistic signature (σ_p = 0.03 cm, σ_o = 0.03°, σ_e = 0.3°): after
    Newton-Raphson 2.8 % of the converged targets exceed it (worst 2e-7 cm,
    4.4e-7°); after Jacobi, whose convergence is only linear, 96 % do (worst
    3e-5 cm away from singularities, 4e-2 cm next to them). The solvers
    therefore also require the pose error to be below ``position_tol_cm`` and
    ``orientation_tol_rad`` (defaults 1e-7 cm and 1e-10 rad); the extra
    iterations are the "polishing" steps (at most one for Newton-Raphson).
    Pass ``None`` for both to get the dissertation's rule unchanged.

Task axes (Newton-Raphson only)
    A robot with fewer than six joints cannot reach a full 6-D pose: a
    SCARA-like arm moves its tool in x, y, z and turns it about the vertical
    axis only. ``task_axes`` selects the controlled components of
    ``δ = [dx, dy, dz, rx, ry, rz]`` (indices, in the chain's world frame); the
    other components are dropped from δ and from the Jacobian's rows, so the
    iteration solves the selected equations (least squares / minimum norm when
    they are not square) and the tolerances, the encoder rule, the safeguard
    and the reported errors all refer to the selected components only
    (:attr:`IKResult.task_axes`). :func:`controllable_axes` derives the
    selection from a (design) chain. Default: all six, the dissertation's (5.4).

Status codes (:attr:`IKResult.status`, names in :data:`STATUS_NAMES`)
    ``STATUS_CONVERGED`` (0)
        Encoder rule met and pose error within tolerance.
    ``STATUS_MAX_ITER`` (1)
        Iteration cap reached; the Jacobian at the last iterate is regular.
    ``STATUS_SINGULAR`` (2)
        Iteration cap reached at a near-singular configuration (smallest
        singular value of the unit-scaled Jacobian below :data:`SINGULAR_SIGMA`).
    ``STATUS_UNREACHABLE`` (3)
        The residual stopped decreasing while the steps are below one encoder
        count: a local minimum of the residual, i.e. the target is outside the
        workspace (next to a singularity, rarely, a spurious minimum of a
        reachable target). For the Jacobi method also: the design inverse has
        no solution (only with ``puma_design_inverse(clamp=False)``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import SerialChain, forward_kinematics, is_single_robot
from pipeline.kinematics.ik_stall import STALL_RATIO
from pipeline.kinematics.jacobian import geometric_jacobian, pose_and_jacobian
from pipeline.kinematics.transforms import (
    Array,
    ArrayLike,
    differential_motion,
    invert_transform,
)

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]

#: Stopping rule met and pose error within tolerance.
STATUS_CONVERGED = 0
#: Iteration cap reached at a regular configuration.
STATUS_MAX_ITER = 1
#: Iteration cap reached at a (near-)singular configuration.
STATUS_SINGULAR = 2
#: No progress with sub-resolution steps (outside the workspace), or no design inverse.
STATUS_UNREACHABLE = 3
#: Human-readable names of the status codes.
STATUS_NAMES = {
    STATUS_CONVERGED: "converged",
    STATUS_MAX_ITER: "max_iter",
    STATUS_SINGULAR: "singular",
    STATUS_UNREACHABLE: "unreachable",
}

#: Smallest singular value of the unit-scaled Jacobian (position rows divided by
#: the chain's length scale, ~164 cm for the Puma) below which a target that did
#: not converge is reported singular rather than merely out of iterations. For
#: the Puma's wrist this is |θ5| below ~0.06°, about 12 encoder counts.
SINGULAR_SIGMA = 1e-3

#: Design inverse for the Jacobi method: ``(T (k, 4, 4), q_near (k, n)) -> q (k, n)``.
#: Rows the design model cannot reach on the branch are NaN.
DesignInverse = Callable[[Array, Array], Array]


@dataclass(frozen=True, eq=False)
class IKHistory:
    """Per-iteration record of a solve, for Tables 5-1 and 5-2.

    Row ``k`` is the state after ``k`` updates (row 0 is the start ``q0``).
    ``K`` is the largest iteration count in the batch; a target that stopped
    earlier repeats its final state in the remaining rows.

    Attributes
    ----------
    q : ndarray, shape (K + 1, m, n)
        Joint iterates (rad / cm).
    delta : ndarray, shape (K + 1, m, 6)
        ``differential_motion(F_s(q^k), T*)``: base-frame ``[dx, dy, dz]`` in cm
        (desired minus reached, the X/Y/Z axis errors of Tables 5-1/5-2) and the
        axis-angle rotation vector in radians.
    position_error_cm : ndarray, shape (K + 1, m)
        Radial (Euclidean) position error, cm.
    orientation_error_rad : ndarray, shape (K + 1, m)
        Angle of the residual rotation, radians.
    """

    q: Array
    delta: Array
    position_error_cm: Array
    orientation_error_rad: Array


@dataclass(frozen=True, eq=False)
class IKResult:
    """Outcome of a batched inverse-kinematics solve.

    Attributes
    ----------
    q : ndarray, shape (m, n)
        Final joint coordinates (rad / cm), always finite. Angles are not
        wrapped: they stay in the 2π class reached from ``q0``.
    converged : ndarray of bool, shape (m,)
        ``status == STATUS_CONVERGED``.
    iterations : ndarray of int, shape (m,)
        Number of updates (5.4) or (5.8) applied to each target.
    position_error_cm : ndarray, shape (m,)
        ``|p* − p(q)|`` of the signature model at ``q``, cm.
    orientation_error_rad : ndarray, shape (m,)
        Angle of the residual rotation, radians in [0, π].
    status : ndarray of int, shape (m,)
        One of the ``STATUS_*`` codes (see the module docstring).
    history : IKHistory or None
        Per-iteration record when the solver ran with ``record_history=True``
        (with task axes, δ's unselected components are recorded as 0).
    task_axes : tuple of int
        Components of δ the errors and tolerances refer to (module docstring,
        "Task axes"): ``position_error_cm`` is the norm of the selected
        position components, ``orientation_error_rad`` of the selected
        rotation components. All six unless the solve selected fewer.
    branch_changed : ndarray of bool, shape (m,), or None
        True where a converged solution lies on another configuration branch
        than the one requested (a solver's last resort, see
        :class:`pipeline.control.puma560_solver.PumaSolver`); None where the
        solve had no branch to keep (a start given by the caller).
    """

    q: Array
    converged: BoolArray
    iterations: IntArray
    position_error_cm: Array
    orientation_error_rad: Array
    status: IntArray
    history: IKHistory | None = None
    task_axes: tuple[int, ...] = (0, 1, 2, 3, 4, 5)
    branch_changed: BoolArray | None = None

    @classmethod
    def of_one_target(cls, **fields: Any) -> IKResult:
        """The result of one target (a real-time solver's), every field given but
        ``history`` and ``task_axes`` (their defaults). Filled in directly: the frozen
        dataclass's ``__init__`` sets its nine fields one ``object.__setattr__`` at a
        time, 1.8 µs, a sixth of a one-target solve."""
        result = object.__new__(cls)
        result.__dict__.update(history=None, task_axes=ALL_AXES, **fields)
        return result


# --------------------------------------------------------------------------- helpers

ALL_AXES = (0, 1, 2, 3, 4, 5)


def _task_mask(task_axes: Sequence[int] | None) -> tuple[tuple[int, ...], Array | None]:
    """Validated task axes and the 0/1 mask of δ's components (None: all six)."""
    if task_axes is None:
        return ALL_AXES, None
    axes = tuple(sorted({int(a) for a in task_axes}))
    if not axes or axes[0] < 0 or axes[-1] > 5 or len(axes) != len(tuple(task_axes)):
        raise KinematicsError(
            "bad task axes",
            expected="distinct indices 0-5 into δ = [dx, dy, dz, rx, ry, rz]",
            got=repr(task_axes),
        )
    if axes == ALL_AXES:
        return ALL_AXES, None
    mask = np.zeros(6)
    mask[list(axes)] = 1.0
    return axes, mask


def _masked(delta: Array, mask: Array | None) -> Array:
    """δ (..., 6) with the unselected components set to 0 (unchanged without a mask)."""
    return delta if mask is None else delta * mask


def _masked_rows(J: Array, mask: Array | None) -> Array:
    """Jacobians (..., 6, n) with the unselected rows set to 0."""
    return J if mask is None else J * mask[:, None]


def _prepare(
    chain: SerialChain, T_target: ArrayLike, q0: ArrayLike, resolution: ArrayLike
) -> tuple[Array, Array, Array]:
    """Validate and broadcast the inputs to (m, 4, 4), (m, n), (n,)."""
    T = np.asarray(T_target, float)
    if T.ndim == 2:
        T = T[None]
    if T.ndim != 3 or T.shape[-2:] != (4, 4):
        raise KinematicsError(
            "bad target poses", expected="shape (m, 4, 4) or (4, 4)", got=f"shape {T.shape}"
        )
    m, n = T.shape[0], chain.n_joints
    q_start = np.asarray(q0, float)
    if q_start.shape not in ((n,), (m, n)):
        raise KinematicsError(
            "bad start configurations",
            expected=f"shape ({m}, {n}) or ({n},)",
            got=f"{q_start.shape}",
        )
    q = np.empty((m, n))
    q[...] = q_start
    if np.count_nonzero(np.isfinite(T)) < T.size or np.count_nonzero(np.isfinite(q)) < q.size:
        raise KinematicsError(
            "non-finite target pose or start configuration",
            fix="replace NaN rows (e.g. where the design inverse is unreachable) "
            "by a finite guess such as the home configuration",
        )
    res = np.asarray(resolution, float)
    if res.shape != (n,):
        res = np.broadcast_to(res, (n,))
    if np.count_nonzero(res > 0) < n:
        raise KinematicsError("encoder resolution must be positive", got=repr(res))
    parts = (("links", chain.links, 3), ("base", chain.base, 2), ("tool", chain.tool, 2))
    for name, arr, core in parts:
        if arr.ndim > core + 1 or (arr.ndim == core + 1 and arr.shape[0] not in (1, m)):
            raise KinematicsError(
                f"chain {name} batch does not match the targets",
                expected=f"no batch or a batch of 1 or {m}",
                got=f"shape {arr.shape}",
            )
    return T, q, res


def _take(chain: SerialChain, rows: IntArray, m: int) -> SerialChain:
    """The chain restricted to target ``rows`` (a no-op for an unbatched chain)."""
    links, base, tool = chain.links, chain.base, chain.tool
    if links.ndim == 3 and base.ndim == 2 and tool.ndim == 2:
        return chain

    def pick(a: Array, core: int) -> Array:
        if a.ndim == core:
            return a
        return np.broadcast_to(a, (m, *a.shape[1:]))[rows]

    return SerialChain(
        links=pick(links, 3),
        prismatic=chain.prismatic,
        base=pick(base, 2),
        tool=pick(tool, 2),
        joint_offsets=chain.joint_offsets,
    )


def _unit_weights(length: float) -> Array:
    """Row weights ``[1/L, 1/L, 1/L, 1, 1, 1]`` that make δ and J unit-scaled."""
    return np.array([1.0 / length] * 3 + [1.0] * 3)


def _scaled_svd(J: Array, length: float) -> tuple[Array, Array, Array]:
    """SVD of the Jacobian with its position rows divided by ``length``."""
    U, s, Vt = np.linalg.svd(J * _unit_weights(length)[:, None], full_matrices=False)
    return U, s, Vt


def _damped_step(U: Array, s: Array, Vt: Array, delta_scaled: Array, lam: Array) -> Array:
    """Damped least-squares solution of the scaled ``J dq = δ`` (5.4) from its SVD.

    Parameters
    ----------
    U, s, Vt : ndarray, shapes (k, 6, r), (k, r), (k, r, n)
        SVD of the Jacobian with position rows divided by the length scale.
    delta_scaled : ndarray, shape (k, 6)
        δ with the position part divided by the same length scale.
    lam : ndarray, shape (k,)
        Levenberg-Marquardt damping λ (0: the Newton step ``J⁻¹ δ``).

    Returns
    -------
    dq : ndarray, shape (k, n)
        ``V diag(σ / (σ² + λ²)) Uᵀ δ``. Singular values below 1e-12 σ_max are
        dropped (pseudo-inverse cut-off: far above the ~1e-16 round-off of the
        SVD, far below any physical σ; the Puma's σ_min one encoder count from
        its wrist singularity is ~1e-4), so the step is finite for every finite J.
    """
    keep = s > 1e-12 * s[:, :1]
    gain = np.where(keep, s / np.where(keep, s**2 + lam[:, None] ** 2, 1.0), 0.0)
    coeff = np.einsum("kij,ki->kj", U, delta_scaled) * gain
    dq: Array = np.einsum("kjn,kj->kn", Vt, coeff)
    return dq


#: Safeguard of a Newton-Raphson iteration: candidate steps tried in this order
#: until one reduces the error ``|dp|/L + |rotation|``; the first that does is
#: taken. Far from singularities the plain Newton step always succeeds, so the
#: iteration is (5.4) and converges quadratically.
#: The Newton direction shortened (keeps the direction along near-singular
#: valleys, where damping suppresses exactly the component that is needed):
NEWTON_BACKTRACK = (0.5, 0.25, 0.125)
#: Levenberg-Marquardt steps, λ = factor × the ``damping`` argument (up to 1e4 ×,
#: where the step is a short gradient step):
LM_LAMBDAS = (1.0, 10.0, 100.0, 1e4)


def _trials(damping: float) -> list[tuple[str, float]]:
    """The (kind, value) candidate steps of one Newton-Raphson iteration, in order."""
    out = [("newton", 1.0)] + [("newton", a) for a in NEWTON_BACKTRACK]
    out += [("lm", f * damping) for f in LM_LAMBDAS]
    return out


def _cap_step(dq: Array, limit: Array | float) -> Array:
    """Scale each step so no increment exceeds its ``limit`` (n,).

    The limit is ``max_step`` rad for a revolute joint and ``max_step · length``
    cm for a prismatic one (:func:`_step_limit`). Far from the solution (or at a
    singularity) the linearisation is poor and a full step can throw the
    iterate onto another branch; a uniform scale keeps its direction.
    """
    size = np.abs(dq)
    if np.count_nonzero(size <= limit) == size.size:  # the common case: nothing to scale
        return dq
    worst = np.max(size / limit, axis=-1)
    capped: Array = dq / np.maximum(worst, 1.0)[:, None]
    return capped


def _step_limit(chain: SerialChain, max_step: float, length: float) -> Array | float:
    """Per-joint step limits (n,) of :func:`_cap_step`: rad, or cm for prismatic joints
    (one number for a chain of revolute joints)."""
    if not chain.motion_basis[2]:
        return max_step
    return np.where(chain.prismatic, max_step * length, max_step)


def _errors(delta: Array) -> Array:
    """Radial position error (cm) and rotation angle (rad) of δ vectors (..., 6), as (..., 2)."""
    out: Array = np.sqrt((delta * delta) @ _HALVES)  # a product: numpy sums short axes slowly
    return out


#: Sums of δ's position and rotation components: ``δ² @ _HALVES``.
_HALVES = np.repeat(np.eye(2), 3, axis=0)


def _scaled_error(errors: Array, length: float) -> Array:
    """Scalar pose error ``|dp| / length + |rotation|`` from :func:`_errors` (..., 2)."""
    out: Array = errors @ np.array((1.0 / length, 1.0))
    return out


#: ``step(rows, q, δ, e) -> (q_next, ok, increment, δ_next, errors_next, may_stall)``
#: (see :func:`_iterate`); ``ok`` or ``may_stall`` None: all rows.
StepFn = Callable[
    [IntArray, Array, Array, Array],
    tuple[Array, BoolArray | None, Array, Array, Array, BoolArray | None],
]


def _iterate(
    chain: SerialChain,
    T: Array,
    q: Array,
    delta: Array,
    res: Array,
    max_iter: int,
    step: StepFn,
    position_tol_cm: float | None,
    orientation_tol_rad: float | None,
    record_history: bool,
    length: float,
    stall_patience: int = 1,
    task_axes: tuple[int, ...] = ALL_AXES,
) -> IKResult:
    """Shared loop: apply ``step`` to the active targets until each one stops.

    ``delta`` is δ⁰ = ``differential_motion(T(q0), T*)``, shape (m, 6); ``length``
    the chain's :attr:`~pipeline.kinematics.chain.SerialChain.length_scale`.
    ``step(rows, q_rows, delta_rows, e_rows)`` gets the active rows (sorted; a
    subset of the previous call's), their iterates, δ and scaled errors
    (:func:`_scaled_error`), and returns the next iterate of those rows, a mask
    of rows for which it exists (False: unreachable for the method), the
    method's own increment (the Newton step ``J⁻¹ δ`` of (5.4), the Jacobi step
    of (5.8)), which the encoder rule tests, δ at the next iterate and its
    :func:`_errors`, and a mask of rows that may be declared stalled (False
    while the method still has a remedy to try); either mask None stands for
    all rows. The increments differ from the
    step taken only where a safeguard replaced the method's step: a short
    safeguard step says nothing about being near the solution. ``step`` must
    not modify its arguments.

    A target *stalls* (unreachable) when, in ``stall_patience`` consecutive
    iterations, the step actually taken is below one encoder count, the error
    is above tolerance and it fell by less than ``1 − STALL_RATIO``.
    With ``task_axes`` (δ already restricted to them by ``step``) the singular
    test uses the selected Jacobian rows only.
    """
    m = T.shape[0]
    tol = np.array(
        [
            np.inf if position_tol_cm is None else position_tol_cm,
            np.inf if orientation_tol_rad is None else orientation_tol_rad,
        ]
    )
    status = np.full(m, STATUS_MAX_ITER, np.int64)
    iterations = np.zeros(m, np.int64)
    # The active targets (sorted) and their state; q and delta receive a
    # target's final state when it stops.
    rows = np.arange(m)
    q_a, d_a = q, delta
    e_a = _scaled_error(_errors(delta), length)
    idle = np.zeros(m, np.int64)  # consecutive iterations without progress
    hist_q, hist_d = ([q.copy()], [delta.copy()]) if record_history else ([], [])
    done_iterations = 0
    while done_iterations < max_iter and rows.size:
        q_next, ok, nominal, d_new, err_new, may_stall = step(rows, q_a, d_a, e_a)
        # (np.count_nonzero: the cheapest whole-array test on a few rows)
        if ok is not None and np.count_nonzero(ok) < ok.size:  # unreachable, at its last q
            gone, keep = rows[~ok], ok
            q[gone], delta[gone], iterations[gone] = q_a[~ok], d_a[~ok], done_iterations
            status[gone] = STATUS_UNREACHABLE
            rows, q_a, e_a, idle = rows[keep], q_a[keep], e_a[keep], idle[keep]
            q_next, nominal, d_new = q_next[keep], nominal[keep], d_new[keep]
            err_new = err_new[keep]
            may_stall = None if may_stall is None else may_stall[keep]
        done_iterations += 1
        e_new = _scaled_error(err_new, length)
        small = (np.abs(nominal) < res).all(axis=-1)  # Appendix C.1 step 8
        accurate = (err_new <= tol).all(axis=-1)
        done = small & accurate
        stuck = ~(accurate | (e_new < STALL_RATIO * e_a))
        if may_stall is not None:
            stuck &= may_stall
        if np.count_nonzero(stuck):  # and the step taken is below one count: no progress
            stuck &= (np.abs(q_next - q_a) < res).all(axis=-1)
        idle = (idle + 1) * stuck
        stalled = idle >= stall_patience
        q_a, d_a, e_a = q_next, d_new, e_new
        stop = done | stalled
        if np.count_nonzero(stop):
            fin = rows[stop]
            q[fin], delta[fin], iterations[fin] = q_a[stop], d_a[stop], done_iterations
            status[rows[stalled]] = STATUS_UNREACHABLE
            status[rows[done]] = STATUS_CONVERGED
            keep = ~stop
            rows, q_a, d_a, e_a, idle = rows[keep], q_a[keep], d_a[keep], e_a[keep], idle[keep]
        if record_history:
            hist_q.append(q.copy())
            hist_d.append(delta.copy())
            hist_q[-1][rows], hist_d[-1][rows] = q_a, d_a
    q[rows], delta[rows], iterations[rows] = q_a, d_a, done_iterations

    mark_singular(chain, q, status, task_axes)
    errors = _errors(delta)  # |dp| and the rotation angle of the final pose error
    history = None
    if record_history:
        hq, hd = np.stack(hist_q), np.stack(hist_d)
        he = _errors(hd)
        history = IKHistory(
            q=hq, delta=hd, position_error_cm=he[..., 0], orientation_error_rad=he[..., 1]
        )
    return _result(q, status, iterations, errors, history, task_axes)


def mark_singular(
    chain: SerialChain, q: Array, status: IntArray, task_axes: tuple[int, ...] = ALL_AXES
) -> None:
    """Set ``status`` (m,) to :data:`STATUS_SINGULAR` where it is :data:`STATUS_MAX_ITER`
    and the unit-scaled Jacobian (of the ``task_axes`` rows) at ``q`` (m, n) has its
    smallest singular value below :data:`SINGULAR_SIGMA`; in place."""
    left = np.flatnonzero(status == STATUS_MAX_ITER)
    if left.size:
        _, mask = _task_mask(task_axes)
        J = _masked_rows(geometric_jacobian(_take(chain, left, len(q)), q[left]), mask)
        rank = min(len(task_axes), chain.n_joints)  # the masked rows add zero singular values
        s_min = _scaled_svd(J, chain.length_scale)[1][:, rank - 1]
        status[left[s_min < SINGULAR_SIGMA]] = STATUS_SINGULAR


def _result(
    q: Array,
    status: IntArray,
    iterations: IntArray,
    errors: Array,
    history: IKHistory | None = None,
    task_axes: tuple[int, ...] = ALL_AXES,
) -> IKResult:
    """An :class:`IKResult` from final iterates, statuses, counts and :func:`_errors` (m, 2)."""
    return IKResult(
        q=q,
        converged=status == STATUS_CONVERGED,
        iterations=iterations,
        position_error_cm=errors[:, 0],
        orientation_error_rad=errors[:, 1],
        status=status,
        history=history,
        task_axes=task_axes,
    )


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


# --------------------------------------------------------------------------- solvers


def newton_raphson(
    chain: SerialChain,
    T_target: ArrayLike,
    q0: ArrayLike,
    resolution: ArrayLike,
    max_iter: int = 50,
    damping: float = 1e-3,
    *,
    position_tol_cm: float | None = 1e-7,
    orientation_tol_rad: float | None = 1e-10,
    max_step: float = 0.5,
    record_history: bool = False,
    task_axes: Sequence[int] | None = None,
    compiled: bool = True,
) -> IKResult:
    """Invert a (signature) model by the Newton-Raphson iteration (5.4), Appendix C.1.

    Each iteration evaluates ``δ = differential_motion(T(q), T*)`` in base
    coordinates (as (5.4) defines it; Appendix C.1 steps 3-5 express it in tool
    coordinates instead, with the Jacobian to match) and the geometric Jacobian
    ``J(q)`` (same base frame, rows ``v`` then ``ω``), solves ``J dq = δ`` by LU
    (the SVD pseudo-inverse where J is singular or not square) and sets
    ``q ← q + dq``. Where that Newton step does not reduce the error
    (far from the solution, or next to a singularity) a safeguard replaces it
    by a shorter or damped step (see ``damping``); steps never contain NaN.
    Targets stop independently (module docstring: stopping rule and status).

    Parameters
    ----------
    chain : SerialChain
        Model to invert (the identified signature ``F_s``), unbatched or with a
        batch of ``m`` robots matching the targets.
    T_target : array_like, shape (m, 4, 4) or (4, 4)
        Desired tool poses ``T*`` in the chain's world frame, cm.
    q0 : array_like, shape (m, n) or (n,)
        Initial estimates (rad / cm), normally the design model's closed-form
        inverse on the desired branch (Section 5.2). Must be finite.
    resolution : array_like, shape (n,) or scalar
        Encoder resolution of each joint in rad (revolute) or cm (prismatic).
    max_iter : int
        Iteration cap per target. Reachable Puma targets need 2-4 (up to ~10
        within a few degrees of a singularity); 50 leaves room for slow,
        linearly converging singular targets.
    damping : float
        Smallest Levenberg-Marquardt λ of the safeguard, on the Jacobian with
        position rows divided by the chain's length scale L. Each iteration
        takes the plain Newton step if it reduces the error ``|dp|/L +
        |rotation|``; otherwise the Newton step shortened by 2, 4, 8
        (:data:`NEWTON_BACKTRACK`), then damped steps with λ = damping × 1, 10,
        100, 1e4 (:data:`LM_LAMBDAS`), the first that descends. 1e-3 equals
        :data:`SINGULAR_SIGMA`: the first damped step already bounds the
        components along singular values below it (gain ≤ 1/(2λ)).
    position_tol_cm, orientation_tol_rad : float or None
        Pose-error tolerances required in addition to the encoder rule. The
        defaults sit an order of magnitude below the 1e-6 cm / 1e-7° accuracy
        targeted and several orders above double-precision round-off
        (~1e-13 cm, 1e-15 rad for the Puma). ``None`` disables the check.
    max_step : float
        Largest revolute increment per iteration (rad); prismatic increments are
        limited to ``max_step · L`` cm. Steps from the design start are ~0.01 rad
        (a few tenths of a radian next to a singularity, where 0.5 cm of model
        error moves the solution far); 0.5 rad only stops a near-singular
        Newton step from flinging the iterate onto another branch.
    record_history : bool
        Keep the per-iteration :class:`IKHistory`.
    task_axes : sequence of int or None
        Controlled components of δ = [dx, dy, dz, rx, ry, rz] in the chain's
        world frame, e.g. ``(0, 1, 2, 5)`` (position and rotation about Z) for
        a SCARA-like arm whose joint axes are parallel to the world Z (module
        docstring, "Task axes"; :func:`controllable_axes`). None: all six.
    compiled : bool
        For an unbatched six-joint chain on all six axes without history, run
        the plain Newton iterations compiled
        (:mod:`pipeline.kinematics.ik_compiled`; measured on robot3: one target
        25 µs instead of 430 µs, a batch of 20,000 3.0-3.6 µs per target
        instead of 8-10 µs). Fallback order per target, each from where the
        previous one stopped: (1) plain Newton steps (5.4); (2) where a Newton
        step does not descend, the Jacobian is singular, the target stalls or
        the iteration cap is reached, Levenberg-Marquardt steps in the same
        kernel (:func:`pipeline.kinematics.ik_compiled._levenberg_marquardt`);
        (3) where those find no step that lowers the error (a minimum of the
        residual), the numpy iteration from the target's start, which gives
        the status. On robot3 (100,000 reachable targets of one branch) (2)
        brings the targets left unsolved from 105 to 70. Where both solve a
        target they agree to the pose tolerances; False: numpy only.

    Returns
    -------
    IKResult
    """
    T, q, res = _prepare(chain, T_target, q0, resolution)
    axes, mask = _task_mask(task_axes)
    if compiled and mask is None and not record_history and ik_compilable(chain):
        return _newton_compiled(
            chain, T, q, res, max_iter, damping, position_tol_cm, orientation_tol_rad, max_step
        )
    m = T.shape[0]
    length = chain.length_scale
    T_q, J_q = pose_and_jacobian(chain, q)  # Appendix C.1 steps 1-2 at q⁰
    delta0 = _masked(differential_motion(T_q, T), mask)
    limit = _step_limit(chain, max_step, length)
    # The rows of the last step, J(q^k) from the pass that evaluated q^k and
    # their targets (the active rows only shrink, so they are found among them).
    evaluated: list[tuple[IntArray, Array, Array]] = [(np.arange(m), J_q, T)]

    def step(
        rows: IntArray, q_rows: Array, delta_rows: Array, e_rows: Array
    ) -> tuple[Array, BoolArray | None, Array, Array, Array, BoolArray | None]:
        last_rows, J, T_rows = evaluated[0]
        if rows.size != last_rows.size:
            keep = np.searchsorted(last_rows, rows)
            J, T_rows = J[keep], T_rows[keep]
        J = _masked_rows(J, mask)
        newton = _newton_step(J, delta_rows, length)  # Eq. (5.4): J⁻¹ δ
        q_out = q_rows + _cap_step(newton, limit)  # C.1 step 7
        T_out, J_out = pose_and_jacobian(_take(chain, rows, m), q_out)
        d_out = _masked(differential_motion(T_out, T_rows), mask)
        err_out = _errors(d_out)
        better = _scaled_error(err_out, length) < e_rows
        if np.count_nonzero(better) < better.size:  # the Newton step did not descend
            bad = np.flatnonzero(~better)
            sub = _take(chain, rows[bad], m)
            q_out[bad] = _safeguard(
                sub,
                T_rows[bad],
                q_rows[bad],
                delta_rows[bad],
                J[bad],
                newton[bad],
                damping,
                max_step,
                mask,
            )
            T_bad, J_out[bad] = pose_and_jacobian(sub, q_out[bad])
            d_out[bad] = _masked(differential_motion(T_bad, T_rows[bad]), mask)
            err_out[bad] = _errors(d_out[bad])
        evaluated[0] = rows, J_out, T_rows
        return q_out, None, newton, d_out, err_out, None

    return _iterate(
        chain,
        T,
        q,
        delta0,
        res,
        max_iter,
        step,
        position_tol_cm,
        orientation_tol_rad,
        record_history,
        length,
        task_axes=axes,
    )


def ik_compilable(chain: SerialChain) -> bool:
    """Whether :mod:`pipeline.kinematics.ik_compiled` can solve for ``chain``: one
    robot (no batch axis), a square Jacobian (six joints) and homogeneous
    transforms (:func:`~pipeline.kinematics.ik_compiled.homogeneous`)."""
    from pipeline.kinematics.ik_compiled import homogeneous

    return (
        is_single_robot(chain) and chain.n_joints == 6
        and homogeneous(chain.base, chain.links, chain.tool)
    )  # fmt: skip


def _newton_compiled(
    chain: SerialChain,
    T: Array,
    q0: Array,
    res: Array,
    max_iter: int,
    damping: float,
    position_tol_cm: float | None,
    orientation_tol_rad: float | None,
    max_step: float,
) -> IKResult:
    """:func:`newton_raphson` by the compiled plain iteration, the numpy iteration for
    the targets it defers (same arguments, after :func:`_prepare`)."""
    from pipeline.kinematics.ik_compiled import plain_newton

    n, length = chain.n_joints, chain.length_scale
    limit = np.broadcast_to(_step_limit(chain, max_step, length), (n,))
    tol_p = np.inf if position_tol_cm is None else position_tol_cm
    tol_o = np.inf if orientation_tol_rad is None else orientation_tol_rad
    q, outcome, iterations, delta = plain_newton(
        chain.base, chain.links, chain.tool, np.asarray(chain.joint_offsets), chain.prismatic,
        T, q0, res, limit, max_iter, length, tol_p, tol_o,
    )  # fmt: skip
    return finish_deferred(
        chain, T, q0, res, q, outcome, iterations, delta, max_iter=max_iter, damping=damping,
        position_tol_cm=position_tol_cm, orientation_tol_rad=orientation_tol_rad,
        max_step=max_step,
    )  # fmt: skip


def finish_deferred(
    chain: SerialChain,
    T: Array,
    q0: Array,
    res: Array,
    q: Array,
    outcome: IntArray,
    iterations: IntArray,
    delta: Array,
    *,
    max_iter: int = 50,
    damping: float = 1e-3,
    position_tol_cm: float | None = 1e-7,
    orientation_tol_rad: float | None = 1e-10,
    max_step: float = 0.5,
) -> IKResult:
    """The :class:`IKResult` of a compiled solve (:mod:`pipeline.kinematics.ik_compiled`).

    ``q``, ``outcome``, ``iterations``, ``delta`` (m, n), (m,), (m,), (m, 6) are the
    kernel's outputs for targets ``T`` (m, 4, 4) started at ``q0`` (m, n); rows
    the kernel deferred are solved again by the numpy iteration from ``q0``
    (the fallback's last stage, :func:`newton_raphson`), which gives their
    status. ``q`` and ``iterations`` are updated in place; the remaining
    arguments are those of :func:`newton_raphson`.
    """
    from pipeline.kinematics.ik_compiled import FAST_CONVERGED

    errors = _errors(delta)
    status = np.full(len(q), STATUS_CONVERGED, np.int64)
    deferred = np.flatnonzero(outcome != FAST_CONVERGED)
    if deferred.size:
        rest = newton_raphson(
            chain, T[deferred], q0[deferred], res, max_iter, damping,
            position_tol_cm=position_tol_cm, orientation_tol_rad=orientation_tol_rad,
            max_step=max_step, compiled=False,
        )  # fmt: skip
        q[deferred], iterations[deferred], status[deferred] = rest.q, rest.iterations, rest.status
        errors[deferred, 0] = rest.position_error_cm
        errors[deferred, 1] = rest.orientation_error_rad
    return _result(q, status, iterations, errors)


def _newton_step(J: Array, delta: Array, length: float) -> Array:
    """The Newton increment ``dq = J⁻¹ δ`` of (5.4), rows (k, 6, n) and (k, 6).

    A square Jacobian is solved by LU (row scaling does not change the
    solution); an exactly singular or non-square one by the SVD pseudo-inverse
    of the unit-scaled Jacobian (minimum-norm least squares, see
    :func:`_damped_step`).
    """
    k, _, n = J.shape
    if n == 6 and k:
        try:
            dq = np.linalg.solve(J, delta[..., None])[..., 0]
            if np.count_nonzero(np.isfinite(dq)) == dq.size:
                return np.asarray(dq, float)
        except np.linalg.LinAlgError:
            pass
    U, sv, Vt = _scaled_svd(J, length)
    return _damped_step(U, sv, Vt, delta * _unit_weights(length), np.zeros(k))


def _safeguard(
    chain: SerialChain,
    T: Array,
    q: Array,
    delta: Array,
    J: Array,
    newton: Array,
    damping: float,
    max_step: float,
    mask: Array | None = None,
) -> Array:
    """Safeguarded steps for rows where the plain Newton step did not descend.

    Tries the Newton step shortened by 2, 4, 8 (:data:`NEWTON_BACKTRACK`), then
    Levenberg-Marquardt steps (:data:`LM_LAMBDAS`), and returns, per row, the
    first candidate that reduces the error ``|dp|/L + |rotation|``. Rows for
    which none does keep ``q``: the shared loop reads that as a stall (a local
    minimum of the residual) or, at round-off level, as convergence.

    Parameters
    ----------
    chain : SerialChain
        The chain restricted to these rows.
    T, q, delta, J, newton : ndarray, shapes (k, 4, 4), (k, n), (k, 6), (k, 6, n), (k, n)
        Targets, current iterates, their δ, Jacobian and Newton increment
        (δ and J already restricted to the task axes).
    mask : ndarray, shape (6,), or None
        0/1 selection of δ's components (task axes); None: all six.

    Returns
    -------
    q_next : ndarray, shape (k, n)
    """
    length = chain.length_scale
    limit = _step_limit(chain, max_step, length)
    d_scaled = delta * _unit_weights(length)
    e_old = _scaled_error(_errors(delta), length)
    trials = _trials(damping)[1:]  # [0] is the plain Newton step
    q_out = q.copy()
    todo = np.arange(q.shape[0])
    # JᵀJ and Jᵀδ (unit-scaled) of the rows reaching a damped step, made once.
    normal: tuple[IntArray, Array, Array] | None = None
    start = 0
    while todo.size and start < len(trials):
        # Several candidates per row in one forward-kinematics call while the
        # rows are few (per-call overhead), one at a time for many rows.
        chunk = trials[start : start + max(1, SAFEGUARD_POSES // todo.size)]
        start += len(chunk)
        steps = []
        for kind, value in chunk:
            if kind == "newton":  # shortened Newton step
                dq = value * newton[todo]
            else:  # "lm": Levenberg-Marquardt step, λ = value
                if normal is None:
                    Js = J[todo] * _unit_weights(length)[:, None]
                    Jst = Js.swapaxes(-1, -2)
                    normal = (todo, Jst @ Js, (Jst @ d_scaled[todo, :, None])[..., 0])
                at = np.searchsorted(normal[0], todo)
                dq = _lm_step(normal[1][at], normal[2][at], value)
            steps.append(q[todo] + _cap_step(dq, limit))
        rows = np.tile(todo, len(chunk))  # candidate-major
        q_try = np.concatenate(steps)
        T_try = forward_kinematics(_take(chain, rows, q.shape[0]), q_try)
        d_try = _masked(differential_motion(T_try, T[rows]), mask)
        descends = _scaled_error(_errors(d_try), length) < e_old[rows]
        descends = descends.reshape(len(chunk), todo.size)
        found = descends.any(axis=0)
        first = descends.argmax(axis=0) * todo.size + np.arange(todo.size)  # first that descends
        q_out[todo[found]] = q_try[first[found]]
        todo = todo[~found]
    return q_out


def _lm_step(gram: Array, rhs: Array, lam: float) -> Array:
    """Levenberg-Marquardt step ``(JᵀJ + λ² I)⁻¹ Jᵀ δ`` of the unit-scaled system.

    Parameters
    ----------
    gram, rhs : ndarray, shapes (k, n, n), (k, n)
        ``JᵀJ`` and ``Jᵀδ`` with J's and δ's position rows divided by the length
        scale (see :func:`_scaled_svd`).
    lam : float
        Damping λ > 0. The safeguard's smallest, 1e-3, bounds the condition
        number of ``JᵀJ + λ² I`` by ~1e7 (σ_max² ≲ 10 for the unit-scaled Puma
        Jacobian), so the normal equations lose at most ~1e-9 of the step's
        relative accuracy: immaterial for a trial step that is kept only if it
        reduces the error.

    Returns
    -------
    dq : ndarray, shape (k, n)
        Equal to ``V diag(σ / (σ² + λ²)) Uᵀ δ`` of :func:`_damped_step`.
    """
    n = gram.shape[-1]
    dq = np.linalg.solve(gram + lam**2 * np.eye(n), rhs[..., None])[..., 0]
    return np.asarray(dq, float)


#: Candidate poses the safeguard evaluates per forward-kinematics call: all
#: remaining candidates of up to ~290 rows at once (the rows left to a
#: safeguard are typically 50-150 of 100,000), one candidate at a time for
#: more than 2048 rows.
SAFEGUARD_POSES = 2048


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
        cannot reach ``T``. See :func:`puma_design_inverse`.
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
        As for :func:`newton_raphson`.
    record_history : bool
        Keep the per-iteration :class:`IKHistory`.
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


#: A row of the unit-scaled Jacobian counts as identically zero below this fraction
#: of the largest entry over the samples: exact design geometry (α = 0° or 180°)
#: leaves ~1e-16 of round-off in the rows it cannot move, a real coupling (an axis
#: tilted by even 1e-6 rad) is orders of magnitude above 1e-9.
DEAD_ROW_FRACTION = 1e-9


def controllable_axes(chain: SerialChain, q: ArrayLike) -> tuple[int, ...]:
    """Components of δ = [dx, dy, dz, rx, ry, rz] a chain can move (task axes).

    A row of the geometric Jacobian (world frame, position rows divided by
    the length scale) that vanishes at every sample configuration is a pose
    component no joint motion changes: for a SCARA-like arm whose revolute
    axes are parallel to the world Z, ``rx`` and ``ry``. The remaining
    components are the task axes, e.g. ``(0, 1, 2, 5)``. Where more
    components move than the chain has joints (a 5-joint arm moves all six),
    no component is free of the others and only the position is controlled,
    ``(0, 1, 2)``. Evaluate on the *design* model: identified models have
    slightly tilted axes, which move every component a little.

    Parameters
    ----------
    chain : SerialChain
        Unbatched chain.
    q : array_like, shape (k, n)
        Sample configurations (rad / cm), generic (not all singular).

    Returns
    -------
    axes : tuple of int
        Sorted indices into δ; all six for an arm that moves all six with six
        or more joints.

    Raises
    ------
    KinematicsError
        When even the moving position components outnumber the joints (a
        two-joint arm that moves x, y and z): choose ``task_axes`` by hand.
    """
    J = geometric_jacobian(chain, np.atleast_2d(np.asarray(q, float)))
    w = _unit_weights(chain.length_scale)
    size = np.abs(J * w[:, None]).max(axis=(0, 2))  # (6,): largest entry of each row
    live = tuple(int(i) for i in np.flatnonzero(size > DEAD_ROW_FRACTION * size.max()))
    n = chain.n_joints
    if len(live) <= n:
        return live
    position = tuple(i for i in live if i < 3)
    if len(position) > n:
        raise KinematicsError(
            f"cannot choose task axes for a {n}-joint chain",
            expected=f"at most {n} independent pose components",
            got=f"{len(position)} position components move",
            fix="pass task_axes explicitly",
        )
    return position
