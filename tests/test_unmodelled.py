"""The unmodelled error (issue 41): the fit residual beyond the noise the fit weighs,
u² = ms (1 − 1/s²), recovered from residuals of a known noise and a known unmodelled error."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.refine.unmodelled import SIGNIFICANCE, unmodelled_error


def _residuals(sigma: float, u: float, k: int = 20_000, seed: int = 0) -> np.ndarray:
    """Isotropic 3-D residuals: noise σ per axis and an unmodelled error of RMS length u."""
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, sigma, (k, 3)) + rng.normal(0.0, u / np.sqrt(3.0), (k, 3))


def _chi2(r: np.ndarray, sigma: float) -> float:
    return float(np.sum(r**2) / sigma**2)


@pytest.mark.parametrize("u", [0.003, 0.01, 0.047])
def test_a_known_unmodelled_error_is_recovered(u: float) -> None:
    sigma, p = 0.005, 40  # a UR10-like σ, 40 parameters
    r = _residuals(sigma, u)
    dof = 3 * len(r) - p
    got = unmodelled_error(r, p, _chi2(r, sigma) * dof / (3 * len(r)), dof)
    assert got.p_value is not None and got.p_value < SIGNIFICANCE
    assert got.rms_cm == pytest.approx(u, rel=0.03)  # 20,000 points: ~1 % sampling


def test_noise_alone_has_none() -> None:
    """Residuals of the stated noise: χ² within its spread, u = 0 (the prediction is the
    parameters' alone, as before issue 41)."""
    sigma = 0.005
    r = _residuals(sigma, 0.0, seed=3)
    dof = 3 * len(r)
    got = unmodelled_error(r, 0, _chi2(r, sigma), dof)
    assert got.rms_cm == 0.0 and got.p_value is not None and got.p_value > SIGNIFICANCE


def test_without_a_stated_noise_the_whole_residual_counts() -> None:
    r = _residuals(0.005, 0.0, seed=4)
    got = unmodelled_error(r, 30, chi2=1e-6, dof=3 * len(r) - 30, noise_stated=False)
    assert got.p_value is None
    ms = np.mean(np.sum(r**2, axis=1)) * 3 * len(r) / (3 * len(r) - 30)
    assert got.rms_cm == pytest.approx(np.sqrt(ms), rel=1e-12)


def test_no_point_or_no_degree_of_freedom() -> None:
    assert unmodelled_error(np.zeros((0, 3)), 5, 1.0, 0).rms_cm == 0.0
    assert unmodelled_error(np.full((4, 3), np.nan), 5, 1.0, 7).points == 0
