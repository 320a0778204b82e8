"""Levenberg-Marquardt on the normal equations, with a robust loss by reweighting.

The refinement's problems are tall and thin: ~50,000 whitened slant ranges and ~80
parameters (a sonic session at the range level). scipy's ``least_squares`` takes an SVD
(trust-region reflective) or a QR (MINPACK) of the whole ``R × P`` Jacobian at every
iteration: measured 1.15 s per SVD on robot3, ~10 s a session. The Gauss-Newton step needs
only ``JᵀWJ`` (P × P) and ``JᵀWr``, so the solve asks the problem for them and damps them
(Marquardt's scaled diagonal, Nielsen's update of μ). The problem forms them from its
structure (:func:`pipeline.refine.solve.normal_equations`) and only at accepted points: a
rejected step costs one residual evaluation.

Robust loss (scipy's ``soft_l1``, ``huber``, ``cauchy``, ``arctan`` in units of ``f_scale``
whitened σ; ``linear`` = none): iteratively reweighted least squares, the weight of a
residual ``w = ρ'(z)``, ``z = (r / f_scale)²``, recomputed at every accepted point; the cost
is ``½ Σ f_scale² ρ(z)``. Columns are scaled by ``sqrt(diag(JᵀWJ))`` (scipy's
``x_scale="jac"``), so cm, radians and speed ratios are commensurate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
#: ``normal(w) -> (JᵀWJ, JᵀWr)`` at one point, ``w`` (R,) the residuals' weights.
Normal = Callable[[Array], tuple[Array, Array]]

#: The robust losses, scipy.optimize.least_squares' names and definitions.
LOSSES = ("linear", "soft_l1", "huber", "cauchy", "arctan")


def rho(loss: str, z: Array) -> tuple[Array, Array]:
    """``ρ(z)`` and ``ρ'(z)`` of scipy's losses (``z`` = squared scaled residual)."""
    if loss == "linear":
        return z, np.ones_like(z)
    if loss == "soft_l1":
        s = np.sqrt(1.0 + z)
        return 2.0 * (s - 1.0), 1.0 / s
    if loss == "huber":
        big = z > 1.0
        s = np.sqrt(np.where(big, z, 1.0))
        return np.where(big, 2.0 * s - 1.0, z), np.where(big, 1.0 / s, 1.0)
    if loss == "cauchy":
        return np.log1p(z), 1.0 / (1.0 + z)
    if loss == "arctan":
        return np.arctan(z), 1.0 / (1.0 + z * z)
    raise ValueError(loss)


@dataclass(frozen=True)
class LMResult:
    x: Array
    r: Array  # (R,) residuals at x
    information: Array  # (P, P) JᵀWJ at x
    weights: Array  # (R,) robust weights at x
    cost: float  # ½ Σ f² ρ
    iterations: int  # accepted steps
    evaluations: int
    converged: bool
    message: str


def levenberg_marquardt(
    fun: Callable[[Array], tuple[Array, Normal]],
    x0: Array,
    loss: str = "linear",
    f_scale: float = 1.0,
    tol: float = 1e-15,
    max_evaluations: int = 200,
    start: tuple[Array, Normal] | None = None,
) -> LMResult:
    """Minimise ``½ Σ f² ρ((r/f)²)`` over ``x`` from ``x0``; ``fun(x) -> (r, normal)``
    (:data:`Normal`; it is called only at accepted points). ``start``: ``fun(x0)`` when
    the caller has it already."""
    f2 = f_scale * f_scale

    def state(r: Array, normal: Normal) -> tuple[Array, Normal, Array, float]:
        rho_z, w = rho(loss, r * r / f2)
        return r, normal, w, 0.5 * f2 * float(rho_z.sum())

    x = np.asarray(x0, float).copy()
    r, normal, w, cost = state(*(fun(x) if start is None else start))
    A: Array | None = None  # JᵀWJ at x, once formed
    evaluations, iterations, mu, nu = 1, 0, -1.0, 2.0
    message = "the evaluation limit was reached"
    converged = False
    while evaluations < max_evaluations:
        A, g = normal(w)
        d = np.sqrt(np.diag(A))
        d[d == 0.0] = 1.0
        As = A / np.outer(d, d)
        gs = g / d
        if np.max(np.abs(gs), initial=0.0) <= tol * max(1.0, np.sqrt(2.0 * cost)):
            converged, message = True, "the gradient vanished"
            break
        if mu < 0.0:
            mu = 1e-3
        while evaluations < max_evaluations:
            try:
                hs = np.linalg.solve(As + mu * np.eye(len(gs)), -gs)
            except np.linalg.LinAlgError:
                mu, nu = mu * nu, nu * 2.0
                continue
            predicted = -(hs @ gs + 0.5 * hs @ (As @ hs))
            h = hs / d
            x_new = x + h
            r_new, normal_new, w_new, cost_new = state(*fun(x_new))
            evaluations += 1
            if predicted <= tol * cost and np.isfinite(cost_new):
                # The cost can no longer tell: take this last Gauss-Newton step, which
                # still halves the parameters' distance to the minimum (quadratic rate),
                # so the result does not depend on the cost's rounding (~1e-8 cm before).
                x, r, normal, w, cost = x_new, r_new, normal_new, w_new, cost_new
                A, iterations = None, iterations + 1
                converged, message = True, "the predicted decrease is below rounding"
                break
            if np.isfinite(cost_new) and cost_new < cost:
                gain = (cost - cost_new) / predicted if predicted > 0 else 0.0
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
                nu = 2.0
                small_step = np.linalg.norm(hs) <= tol * (np.linalg.norm(x * d) + tol)
                small_drop = cost - cost_new <= tol * cost
                x, r, normal, w, cost = x_new, r_new, normal_new, w_new, cost_new
                A, iterations = None, iterations + 1
                if small_step or small_drop:
                    converged = True
                    message = "the step" if small_step else "the cost"
                    message += " no longer changed"
                break
            mu, nu = mu * nu, nu * 2.0
            if mu > 1e16:  # no step decreases the cost: at its rounding floor
                converged, message = True, "no step lowers the cost (rounding floor)"
                break
        if converged:
            break
    information = normal(w)[0] if A is None else A
    return LMResult(x, r, information, w, cost, iterations, evaluations, converged, message)


def dense_least_squares(
    residuals: Callable[[Array], Array],
    jacobian: Callable[[Array], Array],
    x0: Array,
    tol: float = 1e-15,
) -> LMResult:
    """:func:`levenberg_marquardt` of ``residuals(x)`` (R,) with its dense ``jacobian(x)``
    (R, P), unweighted: the small fits (a design's registration, an alignment) that would
    otherwise import scipy.optimize (~0.1-0.4 s of CPU in a cold identify)."""

    def fun(x: Array) -> tuple[Array, Normal]:
        r = residuals(x)

        def normal(w: Array) -> tuple[Array, Array]:
            J = jacobian(x)
            Jw = J * w[:, None]
            return Jw.T @ J, Jw.T @ r

        return r, normal

    return levenberg_marquardt(fun, np.asarray(x0, float), tol=tol)
