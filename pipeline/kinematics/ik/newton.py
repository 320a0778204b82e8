"""Newton-Raphson (5.4), Appendix C.1: the numpy iteration with its safeguard, and
the compiled path (:mod:`pipeline.kinematics.ik_compiled`) for one six-joint robot."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.kinematics.chain import SerialChain, is_single_robot
from pipeline.kinematics.ik.batch import (
    BoolArray,
    IntArray,
    _errors,
    _prepare,
    _scaled_error,
    _take,
)
from pipeline.kinematics.ik.iterate import _iterate
from pipeline.kinematics.ik.result import STATUS_CONVERGED, IKResult, _result
from pipeline.kinematics.ik.safeguard import _safeguard
from pipeline.kinematics.ik.steps import _cap_step, _newton_step, _step_limit
from pipeline.kinematics.ik.task import _masked, _masked_rows, _task_mask
from pipeline.kinematics.jacobian import pose_and_jacobian
from pipeline.kinematics.transforms import Array, ArrayLike, differential_motion


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
    Targets stop independently (package docstring: stopping rule and status).

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
        (:data:`.safeguard.NEWTON_BACKTRACK`), then damped steps with λ = damping × 1, 10,
        100, 1e4 (:data:`.safeguard.LM_LAMBDAS`), the first that descends. 1e-3 equals
        :data:`.result.SINGULAR_SIGMA`: the first damped step already bounds the
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
        Keep the per-iteration :class:`.result.IKHistory`.
    task_axes : sequence of int or None
        Controlled components of δ = [dx, dy, dz, rx, ry, rz] in the chain's
        world frame, e.g. ``(0, 1, 2, 5)`` (position and rotation about Z) for
        a SCARA-like arm whose joint axes are parallel to the world Z (package
        docstring, "Task axes"; :func:`.task.controllable_axes`). None: all six.
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
    the targets it defers (same arguments, after :func:`.batch._prepare`)."""
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
