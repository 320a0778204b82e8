"""Line-of-translation (4.44)-(4.47)."""

import numpy as np
import pytest

from pipeline.errors import FeatureError
from pipeline.features.line import fit_line
from tests.feature_data import cross_angle, random_unit


def _line(rng: np.random.Generator, n: int, travel: float):
    v, p0 = random_unit(rng), rng.normal(scale=60.0, size=3)
    s = np.linspace(-0.3 * travel, 0.7 * travel, n)  # increasing joint readings
    return p0 + s[:, None] * v, v, p0


def test_noiseless_line_is_exact(rng: np.random.Generator) -> None:
    for travel in (1.0, 30.0, 200.0):
        pts, v, p0 = _line(rng, 20, travel)
        f = fit_line(pts)
        assert cross_angle(f.direction, v) < 1e-12  # toward increasing reading
        off = f.point - p0
        assert np.linalg.norm(off - (off @ v) * v) < 1e-9  # point on the true line
        assert f.residuals.max() < 1e-9
        np.testing.assert_allclose(np.diff(f.travel), travel / 19, rtol=1e-9)
        assert f.warnings == ()


def test_direction_flips_when_order_is_reversed(rng: np.random.Generator) -> None:
    pts, v, _ = _line(rng, 30, 40.0)
    pts = pts + rng.normal(scale=0.01, size=pts.shape)
    assert fit_line(pts).direction @ v > 0.9999
    assert fit_line(pts[::-1]).direction @ v < -0.9999


def test_noisy_line_direction_error(rng: np.random.Generator) -> None:
    pts, v, _ = _line(rng, 50, 40.0)
    f = fit_line(pts + rng.normal(scale=0.01, size=(300, 50, 3)))
    # Slope std of a regression: σ / sqrt(Σ ŝ²) per perpendicular axis.
    s = np.linspace(0, 40.0, 50)
    predicted = np.sqrt(2.0) * 0.01 / np.sqrt(np.sum((s - s.mean()) ** 2))
    assert 0.85 < np.sqrt(np.mean(cross_angle(f.direction, v) ** 2)) / predicted < 1.15


def test_batch_equals_loop(rng: np.random.Generator) -> None:
    sets = np.stack([_line(rng, 15, t)[0] for t in (5.0, 50.0, 100.0, 10.0)]).reshape(2, 2, 15, 3)
    sets = sets + rng.normal(scale=0.01, size=sets.shape)
    batch = fit_line(sets)
    for i in np.ndindex(2, 2):
        one = fit_line(sets[i])
        np.testing.assert_allclose(batch.direction[i], one.direction, atol=1e-12)
        np.testing.assert_allclose(batch.point[i], one.point, atol=1e-12)
        np.testing.assert_allclose(batch.residuals[i], one.residuals, atol=1e-12)


def test_warnings_and_errors(rng: np.random.Generator) -> None:
    pts, _, _ = _line(rng, 20, 30.0)
    assert any("not uniformly spaced" in w for w in fit_line(pts[rng.permutation(20)]).warnings)
    assert any(w.startswith("B-1") for w in fit_line(pts + rng.normal(size=pts.shape)).warnings)
    with pytest.raises(FeatureError, match="got 2 points"):
        fit_line(pts[:2])
    with pytest.raises(FeatureError, match="coincide"):
        fit_line(np.tile(pts[0], (5, 1)))
