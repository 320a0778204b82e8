"""The held joints' reading errors, shared by every position until the joint moves
(issue 28's sweep plans, issue 41's prediction of a sweep session's accuracy).

The refinement weighs each position by its own noise, the sensor's and every joint's
reading rounding (``resolution² / 12``), as if independent
(:func:`pipeline.refine.points.with_reading_noise`). A joint held still during the other
joints' sweeps is read once and stays put (the simulated servo, and a real arm's brakes):
its rounding is one error shared by every position of that run, which more points do not
average. :func:`sweep_covariance` is the fit's covariance with that sharing (a sandwich
over the fit's independent weights). Math only: arrays and :class:`ChainModel`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.refine.kinematics import ChainModel
from pipeline.refine.problem import reading_tangents
from pipeline.robots.description import RobotDescription
from pipeline.units import joints_to_internal


def reading_noise(
    model: ChainModel, x: np.ndarray, robot: RobotDescription
) -> tuple[np.ndarray, np.ndarray]:
    """``∂p/∂q`` (K, n, 3) of every observation and the variance (n,) of each joint's
    reading: the encoders' rounding, ``resolution² / 12`` (internal units)."""
    res = joints_to_internal(robot.encoder_resolution, robot.prismatic)
    return reading_tangents(model, x), res**2 / 12


def whitening(
    model: ChainModel,
    x: np.ndarray,
    robot: RobotDescription,
    cov_cm2: np.ndarray,
    noise: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """``L⁻¹`` (K, 3, 3) of position noise ``cov_cm2`` (K, 3, 3) plus the readings', as
    the refinement weighs (:func:`pipeline.refine.points.with_reading_noise`); ``noise``:
    :func:`reading_noise` when already computed."""
    g, var = reading_noise(model, x, robot) if noise is None else noise
    cov = cov_cm2 + np.einsum("kni,knj,n->kij", g, g, var)
    return np.asarray(np.linalg.inv(np.linalg.cholesky(cov)))


def sweep_covariance(
    model: Any, x: np.ndarray, robot: RobotDescription, cov_cm2: np.ndarray, sweep: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The whitened Jacobians (K, 3, P) of a sweep session's observations (their
    ``sweep`` ids (K,), in measuring order) and the covariance (P, P) of its whole fit.

    The refinement weighs each position by its own noise, ``cov_cm2`` plus every joint's
    reading noise, as if independent (:func:`pipeline.planning.whitening`). A joint held
    still is read once and stays put (the simulated servo, and a real arm's brakes): its
    reading's rounding is one error shared by every position until the joint moves again,
    i.e. by the sweeps measured before its own and by those after it (and the tool), which
    more points do not average. The fit's covariance is then the sandwich
    ``Σ₀ (Σ_k F_k C_k F_kᵀ + Σ_h Σ_runs var_h v vᵀ) Σ₀`` with ``F_k = J_kᵀ W_kᵀ W_k``
    (the fit's weights), ``C_k`` the independent part (the sensor and the swept joint's
    reading), ``v = Σ_{k ∈ run} F_k ∂p_k/∂q_h`` over a run of positions holding joint
    ``h``, and ``Σ₀`` the fit's own covariance
    (:func:`pipeline.refine.plan.design_covariance`)."""
    from pipeline.refine.plan import design_covariance

    g, var = reading_noise(model, x, robot)
    W = whitening(model, x, robot, cov_cm2, (g, var))
    J = W @ model.position_jacobian(x)
    Sigma0 = design_covariance(J, model.param_units)
    n = g.shape[1]
    swept = sweep[:, None] == np.arange(1, n + 1)[None, :]  # (K, n): the joint moving
    F = np.einsum("kip,kij->kpj", J, W)  # J_kᵀ W_k (P, 3) per observation (whitened J)
    C = cov_cm2 + np.einsum("kni,knj,n,kn->kij", g, g, var, swept)
    H = np.einsum("kpi,kij,kqj->pq", F, C, F)
    for h in range(n):
        run = np.cumsum(swept[:, h])  # a held run ends where joint h moves
        for r in np.unique(run[~swept[:, h]]):
            at = ~swept[:, h] & (run == r)
            v = np.einsum("kpi,ki->p", F[at], g[at, h])
            H += var[h] * np.outer(v, v)
    return J, Sigma0 @ H @ Sigma0
