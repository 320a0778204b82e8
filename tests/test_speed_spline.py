"""The speed-of-sound spline's basis (issue 18): numpy's FITPACK recurrence gives scipy's
``BSpline.design_matrix`` bit for bit, so the refine tables keep their content hashes."""

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
