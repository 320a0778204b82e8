"""Triangulation (6.1)-(6.6), ERRATA form."""

import numpy as np
import pytest

from pipeline.errors import ArmsigError
from pipeline.sensor.geometry import W_AB_CM, W_AC_CM, W_BC_CM, microphones_from_distances
from pipeline.sensor.triangulation import triangulate

W = (W_AB_CM, W_BC_CM, W_AC_CM)


def ranges(p: np.ndarray, w: tuple[float, float, float] = W) -> np.ndarray:
    """Exact slant ranges from points (..., 3) to A, B, C, shape (..., 3)."""
    mics = microphones_from_distances(*w)
    return np.linalg.norm(p[..., None, :] - mics, axis=-1)


def points_in_range(rng: np.random.Generator, n: int, w: tuple[float, float, float] = W):
    """n points with 1 <= z <= 250 cm whose ranges to A, B, C are all 30-250 cm."""
    out = np.empty((0, 3))
    while len(out) < n:
        p = rng.uniform([-150.0, -150.0, 1.0], [300.0, 300.0, 250.0], size=(4 * n, 3))
        s = ranges(p, w)
        out = np.vstack([out, p[np.all((s >= 30.0) & (s <= 250.0), axis=-1)]])
    return out[:n]


@pytest.mark.parametrize("w", [W, (150.0, 140.0, 210.0), (120.0, 160.0, 90.0)])
def test_round_trip(rng: np.random.Generator, w: tuple[float, float, float]) -> None:
    p = points_in_range(rng, 10_000, w)
    err = np.abs(triangulate(ranges(p, w), *w) - p)
    # measured 9e-12 (default) to 2.3e-11 cm; z error grows like 1/z, and z >= 1 cm here
    assert err.max() < 1e-9


def test_batch_equals_loop(rng: np.random.Generator) -> None:
    s = ranges(points_in_range(rng, 60))
    batch = triangulate(s.reshape(3, 20, 3), *W)
    assert batch.shape == (3, 20, 3)
    loop = np.array([triangulate(row, *W) for row in s])
    np.testing.assert_array_equal(batch.reshape(60, 3), loop)


def test_impossible_ranges_are_nan(rng: np.random.Generator) -> None:
    p = points_in_range(rng, 6)
    s = ranges(p)
    s[1] = (10.0, 10.0, 10.0)  # spheres 143 cm apart cannot meet
    s[3, 2] = np.nan  # missing echo
    wall = ranges(np.array([50.0, 60.0, 0.0]))
    s[4] = wall - (0.0, 0.0, 0.01)  # one resolution step too short: spheres miss
    s[5] = wall - (0.0, 0.0, 1e-6)  # far above rounding, so not clipped either
    out = triangulate(s, *W)
    assert np.isnan(out[[1, 3, 4, 5]]).all()
    np.testing.assert_allclose(out[[0, 2]], p[[0, 2]], rtol=0, atol=1e-9)


def test_targets_on_the_wall_are_clipped_not_nan(rng: np.random.Generator) -> None:
    p = points_in_range(rng, 2000)
    p[:, 2] = 0.0  # z² lands on either side of 0 by rounding
    out = triangulate(ranges(p), *W)
    assert np.isfinite(out).all()
    np.testing.assert_allclose(out[:, :2], p[:, :2], rtol=0, atol=1e-9)
    assert np.abs(out[:, 2]).max() < 1e-4  # sqrt of a rounding-size z²


def test_room_side_root_is_chosen() -> None:
    out = triangulate(ranges(np.array([40.0, 50.0, -30.0])), *W)
    np.testing.assert_allclose(out, [40.0, 50.0, 30.0], rtol=0, atol=1e-9)


def test_bad_input_raises() -> None:
    with pytest.raises(ArmsigError, match="shape"):
        triangulate(np.ones((4, 2)), *W)
    with pytest.raises(ArmsigError, match="triangle"):
        triangulate(np.ones(3), 100.0, 50.0, 50.0)
