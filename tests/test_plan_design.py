"""The pose-plan math (pipeline/refine/plan.py): the greedy's Woodbury updates against a
brute-force reference, and the quantile a target is met with against draws."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.refine.plan import (
    PRIOR_SIGMAS,
    TARGET_QUANTILE,
    continuous_design,
    greedy_plan,
    rms_quantile_cm,
)


def _problem(rng: np.random.Generator, K: int = 60, P: int = 7):
    J = rng.normal(size=(K, 3, P))
    B = rng.normal(size=(40, 3, P))
    M = np.einsum("mip,miq->pq", B, B)
    return J, M, ("cm",) * P  # tolerance 1 cm: the internal and the scaled units agree


def test_the_woodbury_greedy_picks_what_a_brute_force_greedy_picks(rng) -> None:
    J, M, units = _problem(rng)
    fast = greedy_plan(J, M, 40, units, 12)
    A = np.eye(J.shape[-1]) / PRIOR_SIGMAS**2
    chosen: list[int] = []
    for _ in range(12):  # every candidate's trace(M (A + JᵀJ)⁻¹) from scratch
        cost = [np.inf if k in chosen else np.trace(M @ np.linalg.inv(A + J[k].T @ J[k]))
                for k in range(len(J))]  # fmt: skip
        c = int(np.argmin(cost))
        chosen.append(c)
        A = A + J[c].T @ J[c]
        np.testing.assert_allclose(
            fast.rms_cm[len(chosen) - 1], np.sqrt(np.trace(M @ np.linalg.inv(A)) / 40), rtol=1e-9
        )
    assert fast.chosen.tolist() == chosen
    # The first steps subtract from the 1e6 prior: rounding ~1e6 · 1e-16 = 1e-10.
    np.testing.assert_allclose(fast.covariance, np.linalg.inv(A), rtol=1e-6, atol=1e-9)


def test_the_quantile_a_target_is_met_with_matches_draws_of_the_parameters(rng) -> None:
    J, M, _ = _problem(rng, K=20)
    Sigma = np.linalg.inv(np.einsum("kip,kiq->pq", J, J))
    d = rng.multivariate_normal(np.zeros(len(Sigma)), Sigma, size=40_000)
    rms = np.sqrt(np.einsum("kp,pq,kq->k", d, M, d) / 40)
    # 40,000 draws pin the empirical 95th percentile to ~0.3 %; the function's 4,000 to ~1 %.
    np.testing.assert_allclose(rms_quantile_cm(Sigma, M, 40), np.quantile(rms, TARGET_QUANTILE),
                               rtol=0.03)  # fmt: skip
    assert rms_quantile_cm(Sigma, M, 40) > np.sqrt(np.trace(M @ Sigma) / 40)  # above the mean


def test_the_continuous_design_of_a_straight_line_is_its_two_ends() -> None:
    """y = a + b x on x in [-1, 1], the error of (a, b) weighed alike (M = I): the
    A-optimal design puts half the weight on each end, trace(A⁻¹) = 2."""
    x = np.linspace(-1.0, 1.0, 21)
    J = np.zeros((21, 3, 2))
    J[:, 0, 0], J[:, 0, 1] = 1.0, x
    design = continuous_design(J, np.eye(2), ("cm", "cm"))
    assert design.bound <= 2.0 + 1e-12 <= design.criterion + 1e-12
    assert design.criterion == pytest.approx(2.0, rel=1e-3)
    assert design.weights[[0, -1]].sum() == pytest.approx(1.0, abs=1e-3)


def test_no_greedy_plan_beats_the_continuous_bound(rng) -> None:
    J, M, units = _problem(rng, K=200)
    design = continuous_design(J, M, units)
    plan = greedy_plan(J, M, 40, units, 15)
    assert np.sqrt(design.bound / 15 / 40) <= plan.rms_cm[-1]
    assert design.bound <= design.criterion <= 1.05 * design.bound  # converged to ~5 %
