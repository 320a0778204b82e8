"""The safeguard of a Newton-Raphson iteration: where the Newton step (5.4) does
not reduce the error, the same direction shortened, then Levenberg-Marquardt
steps, the first candidate that descends."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.ik.batch import IntArray, _errors, _scaled_error, _take
from pipeline.kinematics.ik.steps import _cap_step, _step_limit, _unit_weights
from pipeline.kinematics.ik.task import _masked
from pipeline.kinematics.transforms import Array, differential_motion

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
        scale (see :func:`.steps._scaled_svd`).
    lam : float
        Damping λ > 0. The safeguard's smallest, 1e-3, bounds the condition
        number of ``JᵀJ + λ² I`` by ~1e7 (σ_max² ≲ 10 for the unit-scaled Puma
        Jacobian), so the normal equations lose at most ~1e-9 of the step's
        relative accuracy: immaterial for a trial step that is kept only if it
        reduces the error.

    Returns
    -------
    dq : ndarray, shape (k, n)
        Equal to ``V diag(σ / (σ² + λ²)) Uᵀ δ`` of :func:`.steps._damped_step`.
    """
    n = gram.shape[-1]
    dq = np.linalg.solve(gram + lam**2 * np.eye(n), rhs[..., None])[..., 0]
    return np.asarray(dq, float)


#: Candidate poses the safeguard evaluates per forward-kinematics call: all
#: remaining candidates of up to ~290 rows at once (the rows left to a
#: safeguard are typically 50-150 of 100,000), one candidate at a time for
#: more than 2048 rows.
SAFEGUARD_POSES = 2048
