"""The loop both solvers share: apply a method's step to the active targets until
each one converges, stalls or reaches the iteration cap
(:mod:`pipeline.kinematics.ik`, "Stopping rule")."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.ik.batch import BoolArray, IntArray, _errors, _scaled_error
from pipeline.kinematics.ik.result import (
    STATUS_CONVERGED,
    STATUS_MAX_ITER,
    STATUS_UNREACHABLE,
    IKHistory,
    IKResult,
    _result,
    mark_singular,
)
from pipeline.kinematics.ik.task import ALL_AXES
from pipeline.kinematics.ik_stall import STALL_RATIO
from pipeline.kinematics.transforms import Array

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
    (:func:`.batch._scaled_error`), and returns the next iterate of those rows, a mask
    of rows for which it exists (False: unreachable for the method), the
    method's own increment (the Newton step ``J⁻¹ δ`` of (5.4), the Jacobi step
    of (5.8)), which the encoder rule tests, δ at the next iterate and its
    :func:`.batch._errors`, and a mask of rows that may be declared stalled (False
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
