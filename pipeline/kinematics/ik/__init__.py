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
    ``STATUS_OUT_OF_LIMITS`` (4)
        Converged, but neither the solution nor an equivalent of it on the
        requested branch (±2π, the wrist flip) is inside the joint limits; set by
        the controller (:mod:`pipeline.control.limits`), not by the solvers here.

Modules, in the order a solve uses them
    :mod:`.batch` (validated targets, a batched chain's rows, pose errors),
    :mod:`.task` (task axes), :mod:`.steps` (Newton, damped steps, step caps),
    :mod:`.safeguard` (shortened and Levenberg-Marquardt steps), :mod:`.iterate`
    (the loop both solvers share, the stopping rule), :mod:`.newton` and
    :mod:`.jacobi` (the two solvers), :mod:`.result` (status codes, results).
    The public names are re-exported here.
"""

from __future__ import annotations

from pipeline.kinematics.ik.jacobi import (
    ANDERSON_RCOND,
    JACOBI_SLOW_RATIO,
    JACOBI_STALL_PATIENCE,
    DesignInverse,
    jacobi_iterative,
)
from pipeline.kinematics.ik.newton import finish_deferred, ik_compilable, newton_raphson
from pipeline.kinematics.ik.result import (
    SINGULAR_SIGMA,
    STATUS_CONVERGED,
    STATUS_MAX_ITER,
    STATUS_NAMES,
    STATUS_OUT_OF_LIMITS,
    STATUS_SINGULAR,
    STATUS_UNREACHABLE,
    IKHistory,
    IKResult,
    mark_singular,
)
from pipeline.kinematics.ik.safeguard import LM_LAMBDAS, NEWTON_BACKTRACK
from pipeline.kinematics.ik.task import ALL_AXES, DEAD_ROW_FRACTION, controllable_axes

__all__ = [
    "ALL_AXES",
    "ANDERSON_RCOND",
    "DEAD_ROW_FRACTION",
    "DesignInverse",
    "IKHistory",
    "IKResult",
    "JACOBI_SLOW_RATIO",
    "JACOBI_STALL_PATIENCE",
    "LM_LAMBDAS",
    "NEWTON_BACKTRACK",
    "SINGULAR_SIGMA",
    "STATUS_CONVERGED",
    "STATUS_MAX_ITER",
    "STATUS_NAMES",
    "STATUS_OUT_OF_LIMITS",
    "STATUS_SINGULAR",
    "STATUS_UNREACHABLE",
    "controllable_axes",
    "finish_deferred",
    "ik_compilable",
    "jacobi_iterative",
    "mark_singular",
    "newton_raphson",
]
