"""The refinement's solve: one kinematic model and one measurement block, jointly.

The parameters are ``x = [θ_kin, x_block]`` (:class:`~pipeline.refine.kinematics.ChainModel`'s,
then the block's). The residuals are the block's whitened residuals at the chain's predicted
positions, and the Jacobian chains the two (:mod:`pipeline.refine.block`)::

    J = [ d_p[rows] · ∂p/∂θ[pos[rows]],  d_x ]

solved by Levenberg-Marquardt on the normal equations (:mod:`pipeline.refine.lm`: a robust
loss in whitened units by reweighting). The covariance is Gauss-Newton at the solution,
``(JᵀWJ)⁻¹ · χ²/dof`` with ``W`` the robust weights and ``χ² = 2 · cost`` (the robust χ²;
the plain Σr² for rows within ``f_scale``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError
from pipeline.refine.block import Array, Linearization, MeasurementBlock
from pipeline.refine.kinematics import ChainModel
from pipeline.refine.lm import LOSSES, levenberg_marquardt

#: Solver tolerances: at 1e-15 (relative cost, step and gradient) a noiseless session
#: converges to its rounding floor (audit ~1e-12 cm, well inside the 1e-6 cm acceptance);
#: a noisy one stops on the cost test within ~10 iterations.
TOLERANCE = 1e-15
#: Iteration cap (Jacobian evaluations); a session needs ~5-15.
MAX_EVALUATIONS = 200
#: The recorded-sensor χ² re-solves the kinematics only, warm-started at the solution:
#: ~3 iterations; capped so that a poorly recorded sensor cannot double the stage's time.
RECORDED_EVALUATIONS = 10


@dataclass(frozen=True)
class Problem:
    """A kinematic model, its measurement block, and the robust loss (scipy's names).

    ``keep`` (K,) bool selects the block's positions in the fit (rows of the block that
    depend on no position are always kept); ``fixed_block`` holds the block's own
    parameters at their start values (the sensor as recorded).
    """

    model: ChainModel
    block: MeasurementBlock
    loss: str = "soft_l1"
    f_scale: float = 3.0
    keep: npt.NDArray[np.bool_] | None = None
    fixed_block: bool = False

    @property
    def n_kin(self) -> int:
        return self.model.n_params

    @property
    def n_params(self) -> int:
        return self.model.n_params + len(self.block.x0)


@dataclass(frozen=True)
class Solution:
    """The solver's result and summary (Ceres style: why it stopped is part of it)."""

    x: Array
    covariance: Array  # (P, P), χ²/dof-scaled
    chi2: float
    dof: int
    n_residuals: int
    iterations: int
    status: str
    message: str
    down_weighted: int

    @property
    def sigma(self) -> Array:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def noise_scale(self) -> float:
        return float(np.sqrt(self.chi2 / self.dof)) if self.dof > 0 else float("nan")


def _linearize(problem: Problem, x: Array) -> tuple[Linearization, npt.NDArray[np.bool_]]:
    lin = problem.block.linearize(problem.model.positions(x[: problem.n_kin]), x[problem.n_kin :])
    rows = np.ones(len(lin.r), bool)
    if problem.keep is not None:
        rows = (lin.pos < 0) | problem.keep[np.maximum(lin.pos, 0)]
    return lin, rows


def residuals(problem: Problem, x: Array) -> Array:
    """The whitened residuals at ``x`` (R,)."""
    lin, rows = _linearize(problem, x)
    return lin.r[rows]


def residuals_and_jacobian(problem: Problem, x: Array) -> tuple[Array, Array]:
    """The whitened residuals (R,) and ``∂r/∂x`` (R, n_params) at ``x`` from one
    linearization of the block, per the module docstring."""
    lin, rows = _linearize(problem, x)
    dpdx = problem.model.position_jacobian(x[: problem.n_kin])  # (K, 3, n_kin)
    J = np.zeros((len(lin.r), problem.n_params))
    on = lin.pos >= 0
    J[on, : problem.n_kin] = np.einsum("ri,rij->rj", lin.d_p[on], dpdx[lin.pos[on]])
    J[:, problem.n_kin :] = lin.d_x
    if rows.all():
        return lin.r, J
    return lin.r[rows], J[rows]


def jacobian(problem: Problem, x: Array) -> Array:
    """``∂r/∂x`` (R, n_params), per the module docstring."""
    return residuals_and_jacobian(problem, x)[1]


def solve(problem: Problem, x_start: Array, max_evaluations: int = MAX_EVALUATIONS) -> Solution:
    """Fit ``problem`` from ``x_start`` (module docstring)."""
    if problem.loss not in LOSSES:
        raise ArmsigError(
            f"unknown loss {problem.loss!r}", expected=", ".join(LOSSES), fix="soft_l1"
        )
    free = np.ones(problem.n_params, bool)
    if problem.fixed_block:
        free[problem.n_kin :] = False
    x_fixed = np.asarray(x_start, float).copy()

    def full(z: Array) -> Array:
        x = x_fixed.copy()
        x[free] = z
        return x

    r0 = residuals(problem, x_fixed)
    if not np.isfinite(r0).all():
        raise ArmsigError(
            "refinement: the start gives non-finite residuals",
            expected="finite measurements and a finite start",
            got=f"{int((~np.isfinite(r0)).sum())} of {len(r0)} residuals NaN or inf",
            fix="check the positions table; --param refine.enabled=false skips the refinement",
        )

    def fun(z: Array) -> tuple[Array, Array]:
        r, J = residuals_and_jacobian(problem, full(z))
        return r, (J if free.all() else J[:, free])

    result = levenberg_marquardt(
        fun, x_fixed[free], problem.loss, problem.f_scale, TOLERANCE, max_evaluations
    )
    x = full(result.x)
    n_res = len(result.r)
    dof = n_res - int(free.sum())
    chi2 = 2.0 * float(result.cost)
    cov = np.zeros((problem.n_params, problem.n_params))
    J = result.J
    scale = chi2 / dof if dof > 0 else np.nan
    cov[np.ix_(free, free)] = np.linalg.pinv(J.T @ (J * result.weights[:, None])) * scale
    return Solution(
        x=x,
        covariance=cov,
        chi2=chi2,
        dof=dof,
        n_residuals=n_res,
        iterations=result.iterations,
        status="converged" if result.converged else "not converged",
        message=result.message,
        down_weighted=int((np.abs(result.r) > problem.f_scale).sum()),
    )


def recorded_chi2(problem: Problem, solution: Solution) -> float:
    """χ² with the block's own parameters held at their start (the sensor as recorded):
    a short second solve of the kinematics only, warm-started at ``solution``."""
    if len(problem.block.x0) == 0:
        return solution.chi2
    x = solution.x.copy()
    x[problem.n_kin :] = problem.block.x0
    return solve(replace(problem, fixed_block=True), x, RECORDED_EVALUATIONS).chi2


def refit(problem: Problem, keep_mask: npt.NDArray[np.bool_], x_start: Array) -> Solution:
    """The fit without the positions ``~keep_mask`` (K,) of the block, warm-started at
    ``x_start`` (the holdout's folds)."""
    return solve(replace(problem, keep=np.asarray(keep_mask, bool)), x_start)
