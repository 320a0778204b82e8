"""The speed-of-sound spline (issue 18): numpy's FITPACK recurrence gives scipy's
``BSpline.design_matrix`` bit for bit, and the fit on the normal equations is the dense
design's minimum-norm least squares."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BSpline

from pipeline.sensor.speed_spline import DEGREE, TimeSpline


@pytest.mark.parametrize("seed", range(40))
def test_basis_is_scipys_design_matrix_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    t_min = rng.uniform(-1e3, 1e4)
    t_max = t_min + rng.choice([1e-12, rng.uniform(1.0, 1e4)])  # one cycle, or a session
    spline = TimeSpline.over(t_min, t_max, rng.uniform(5.0, 300.0))
    k = spline.knots
    inside = np.concatenate([rng.uniform(t_min, t_max, 300), k[DEGREE : len(k) - DEGREE]])
    t = np.concatenate([inside, [t_min - 50.0, t_max + 50.0]])  # outside: clipped
    want = BSpline.design_matrix(np.clip(inside, k[DEGREE], k[-DEGREE - 1]), k, DEGREE).toarray()
    want = np.vstack([want, want[[0]] * 0, want[[0]] * 0])
    lo = BSpline.design_matrix(np.array([k[DEGREE]]), k, DEGREE).toarray()[0]
    hi = BSpline.design_matrix(np.array([k[-DEGREE - 1]]), k, DEGREE).toarray()[0]
    want[-2], want[-1] = lo, hi
    got = spline.design(t)
    assert got.tobytes() == want.tobytes()
    idx, val = spline.basis(t)
    np.testing.assert_array_equal(np.take_along_axis(got, idx, axis=1), val)
    assert np.array_equal(idx[:, 1:] - idx[:, :-1], np.ones((len(t), DEGREE), int))


@pytest.mark.parametrize("seed", range(10))
def test_fit_is_the_dense_least_squares(seed: int) -> None:
    rng = np.random.default_rng(seed)
    span = rng.uniform(600.0, 20_000.0)
    t = np.sort(rng.uniform(0.0, span, int(span / 3.0)))  # a cycle every ~3 s
    gap = seed % 2 == 1  # ~8 knot intervals no cycle touches
    if gap:
        t = t[(t < 0.3 * span) | (t > 0.3 * span + 1000.0)]
    v = 1.0 + 0.01 * np.sin(t / 300.0) + rng.normal(0.0, 1e-4, len(t))
    spline = TimeSpline.over(0.0, span, 120.0)
    B = spline.design(t)
    want = np.linalg.lstsq(B, v - v.mean(), rcond=None)[0] + v.mean()
    got = spline.fit(t, v)
    if not gap:  # well determined: the same coefficients
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-11)
        return
    # At a gap's edges a coefficient may be touched only by a basis function's tail
    # (~1e-9): the dense lstsq keeps that direction (coefficients up to ~7e3 seen), the
    # normal equations' cutoff (singular values squared) may drop it. Both fit the data
    # equally well, and a coefficient no cycle touches keeps the mean in both.
    untouched = ~(B != 0).any(axis=0)
    assert untouched.any() and np.all(got[untouched] == v.mean())
    fit_got, fit_want = np.linalg.norm(B @ got - v), np.linalg.norm(B @ want - v)
    assert fit_got <= fit_want * (1 + 1e-9) + 1e-12


def _drift(t: np.ndarray, period_s: float) -> np.ndarray:
    """A relative speed drift of ±3e-4 (0.3 °F) with period ``period_s``, about 1."""
    return 1.0 + 3e-4 * np.sin(2.0 * np.pi * t / period_s + 0.4)


@pytest.mark.parametrize("seed", range(20))
def test_chosen_knots_keep_120_s_for_a_noisy_slow_drift(seed: int) -> None:
    """The rods' per-cycle speed ratio (σ ≈ 1.8e-4 per cycle) of a drift of 15 min and
    more: the 120 s spline follows it to far below the noise, and the choice keeps it
    (the test's 0.1 % per halving, three halvings: 20 seeds)."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, 2500.0, 10_000))
    v = _drift(t, rng.uniform(900.0, 2700.0)) + rng.normal(0.0, 1.8e-4, len(t))
    assert TimeSpline.chosen(0.0, 2500.0, t, v).spacing_s == pytest.approx(2500.0 / 21)


@pytest.mark.parametrize("period_s", [480.0, 900.0, 2700.0])
def test_chosen_knots_follow_an_exact_drift(period_s: float) -> None:
    """Exact samples (a noiseless session's rods) of a drift of 8 to 45 minutes: the knots
    halve down to 15 s or less, where the spline follows an 8-minute drift to 6.4e-10 of
    the speed (1.3e-7 cm over a 200 cm range; at 120 s: 4.3e-6, 8.7e-4 cm)."""
    t = np.arange(0.0, 2500.0, 0.25)
    v = _drift(t, period_s)
    spline = TimeSpline.chosen(0.0, 2500.0, t, v)
    assert spline.spacing_s <= 15.0
    fitted = spline.design(t) @ spline.fit(t, v)
    assert np.abs(fitted - v).max() < 1e-9
    coarse = TimeSpline.over(0.0, 2500.0, 120.0)
    assert np.abs(coarse.design(t) @ coarse.fit(t, v) - v).max() > 1e-9  # the need is real


def test_chosen_knots_keep_120_s_for_still_air() -> None:
    t = np.arange(0.0, 2500.0, 0.25)
    assert TimeSpline.chosen(0.0, 2500.0, t, np.ones_like(t)).spacing_s > 100.0
