"""Feature accuracy statistics (6.8)-(6.13), Table 6-4."""

import numpy as np

from pipeline.features.accuracy import (
    revolute_accuracy,
    sigma_center,
    sigma_delta_full,
    sigma_delta_partial,
    slope_sigmas,
)
from pipeline.features.circle import fit_circle
from pipeline.features.plane import fit_plane_eigen
from tests.feature_data import arc


def test_6_11_is_6_9_for_a_full_turn(rng: np.random.Generator) -> None:
    pts, a, _ = arc(rng, 73, 360.0 * 72 / 73, 40.0)  # 73 equally spaced over the turn
    s_e, s_f = slope_sigmas(pts, a, 0.01)
    expected = sigma_delta_full(0.01, 40.0, 73)
    np.testing.assert_allclose([s_e, s_f], expected, rtol=1e-10)


def test_6_12_approximates_6_9_from_180_to_360(rng: np.random.Generator) -> None:
    for sweep in (180.0, 225.0, 270.0, 300.0, 360.0):
        pts, a, _ = arc(rng, 400, sweep, 40.0)
        exact = slope_sigmas(pts, a, 0.01)[0]
        approx = sigma_delta_partial(0.01, 40.0, 400, np.radians(sweep))
        # Stone's linear fit in X; its worst error on [180°, 360°] is 4.4 % in σ.
        assert abs(approx / exact - 1.0) < 0.05, sweep


def test_empirical_formulas_outside_their_range() -> None:
    x = np.radians([90.0, 140.0, 180.0])
    assert np.isnan(sigma_delta_partial(0.01, 40.0, 100, x[:2])).all()
    assert np.isnan(sigma_center(0.01, 100, x[:1])).all()
    assert np.isfinite(sigma_delta_partial(0.01, 40.0, 100, x[2]))
    # At 360°, (6.13) gives the ~2σ²/n of a full-circle center estimate.
    np.testing.assert_allclose(sigma_center(0.01, 100, 2 * np.pi), np.sqrt(2e-4 / 100), rtol=0.03)


def test_statistics_of_noisy_features(rng: np.random.Generator) -> None:
    clean, _, _ = arc(rng, 100, 300.0, 40.0)
    pts = clean + rng.normal(scale=0.01, size=(200, 100, 3))
    plane = fit_plane_eigen(pts)
    acc = revolute_accuracy(pts, plane, fit_circle(pts, plane))
    # Table 6-4 variances estimate σ² = 1e-4 cm²; 200 sets of 100 pin the mean to ~1 %.
    # The ddof=1 estimate is low by the 3 fitted parameters: (N-3)/(N-1) ≈ 0.98.
    np.testing.assert_allclose(acc.normal_variance.mean(), 1e-4 * 0.98, rtol=0.03)
    np.testing.assert_allclose(acc.radial_variance.mean(), 1e-4 * 0.98, rtol=0.03)
    np.testing.assert_allclose(acc.sigma_delta, acc.sigma_E)
    # The empirical fit (6.12) tracks the exact (6.9) within its 2 % error at 300°.
    np.testing.assert_allclose(acc.sigma_delta_empirical, acc.sigma_delta, rtol=0.03)
    # Each end of the measured sweep errs by ~σ/R = 2.5e-4 rad; 2e-3 is > 5 std.
    np.testing.assert_allclose(acc.sweep, np.radians(300.0), atol=2e-3)


def test_short_sweep_is_less_accurate(rng: np.random.Generator) -> None:
    out = {}
    for sweep in (90.0, 300.0):
        clean, _, _ = arc(rng, 100, sweep, 40.0)
        pts = clean + rng.normal(scale=0.01, size=clean.shape)
        plane = fit_plane_eigen(pts)
        out[sweep] = revolute_accuracy(pts, plane, fit_circle(pts, plane))
    assert out[90.0].sigma_delta > 3.0 * out[300.0].sigma_delta
    assert np.isnan(out[90.0].sigma_delta_empirical) and np.isnan(out[90.0].sigma_c)
