"""What a solve returns: the status codes (:mod:`pipeline.kinematics.ik`, "Status
codes"), :class:`IKResult` and its per-iteration :class:`IKHistory`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.ik.batch import BoolArray, IntArray, _take
from pipeline.kinematics.ik.steps import _scaled_svd
from pipeline.kinematics.ik.task import ALL_AXES, _masked_rows, _task_mask
from pipeline.kinematics.jacobian import geometric_jacobian
from pipeline.kinematics.transforms import Array

#: Stopping rule met and pose error within tolerance.
STATUS_CONVERGED = 0
#: Iteration cap reached at a regular configuration.
STATUS_MAX_ITER = 1
#: Iteration cap reached at a (near-)singular configuration.
STATUS_SINGULAR = 2
#: No progress with sub-resolution steps (outside the workspace), or no design inverse.
STATUS_UNREACHABLE = 3
#: Converged, but no equivalent of the solution on the requested branch (±2π, the wrist
#: flip) is inside the joint limits (set by :mod:`pipeline.control.limits`).
STATUS_OUT_OF_LIMITS = 4
#: Human-readable names of the status codes.
STATUS_NAMES = {
    STATUS_CONVERGED: "converged",
    STATUS_MAX_ITER: "max_iter",
    STATUS_SINGULAR: "singular",
    STATUS_UNREACHABLE: "unreachable",
    STATUS_OUT_OF_LIMITS: "out_of_limits",
}


#: Smallest singular value of the unit-scaled Jacobian (position rows divided by
#: the chain's length scale, ~164 cm for the Puma) below which a target that did
#: not converge is reported singular rather than merely out of iterations. For
#: the Puma's wrist this is |θ5| below ~0.06°, about 12 encoder counts.
SINGULAR_SIGMA = 1e-3


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
        One of the ``STATUS_*`` codes (see the package docstring).
    history : IKHistory or None
        Per-iteration record when the solver ran with ``record_history=True``
        (with task axes, δ's unselected components are recorded as 0). It is the
        first solve's: a restart into the joint limits (:mod:`pipeline.control.limits`)
        adds to ``iterations``, not to the history, so the history may hold fewer than
        ``iterations + 1`` rows.
    task_axes : tuple of int
        Components of δ the errors and tolerances refer to (package docstring,
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
    def of_one_target(
        cls, q: Array, converged: BoolArray, iterations: IntArray, position_error_cm: Array,
        orientation_error_rad: Array, status: IntArray, branch_changed: BoolArray,
    ) -> IKResult:  # fmt: skip
        """The result of one target (a real-time solver's), every field given but
        ``history`` and ``task_axes`` (their defaults). Filled in directly: the frozen
        dataclass's ``__init__`` sets its nine fields one ``object.__setattr__`` at a
        time, 1.8 µs, a sixth of a one-target solve; keywords into ``__dict__.update``
        0.7 µs; one dict given as ``__dict__`` 0.35 µs."""
        result = _new(cls)
        _set(result, "__dict__", {
            "q": q, "converged": converged, "iterations": iterations,
            "position_error_cm": position_error_cm, "orientation_error_rad": orientation_error_rad,
            "status": status, "history": None, "task_axes": ALL_AXES,
            "branch_changed": branch_changed,
        })  # fmt: skip
        return result


_new, _set = object.__new__, object.__setattr__


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
    """An :class:`IKResult` from final iterates, statuses, counts and
    :func:`.batch._errors` (m, 2)."""
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
