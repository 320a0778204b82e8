"""The farthest pair of the repeated regression's first frame (4.26)-(4.29), without the
N×N distance array: the same pair, bit for bit and tie for tie, as that array's argmax."""

import numpy as np
import pytest

from pipeline.features.plane import DENSE_MAX_POINTS, farthest_pair


def _dense(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The N×N array's argmax, as fit_plane_lsq picked it before (issue 18)."""
    d2 = ((p[..., :, None, :] - p[..., None, :, :]) ** 2).sum(-1)
    return np.divmod(d2.reshape(*d2.shape[:-2], -1).argmax(-1), p.shape[-2])


def _ring(rng: np.random.Generator, n: int, sweep_deg: float, noise: float) -> np.ndarray:
    t = np.sort(rng.uniform(0.0, np.radians(sweep_deg), n))
    r = rng.uniform(1.0, 80.0)
    z = rng.normal(0.0, noise, n) if noise else np.zeros(n)
    return np.stack([r * np.cos(t), r * np.sin(t), z], -1) + rng.normal(0.0, 50.0, 3)


@pytest.mark.parametrize("sweep_deg", [5.0, 60.0, 180.0, 270.0, 360.0, 700.0])
@pytest.mark.parametrize("noise", [0.0, 0.01, 3.0])
def test_same_pair_as_the_dense_argmax(sweep_deg, noise, rng: np.random.Generator) -> None:
    for n in (DENSE_MAX_POINTS + 1, 150, 433):
        p = _ring(rng, n, sweep_deg, noise)
        assert tuple(map(int, farthest_pair(p))) == tuple(map(int, _dense(p)))


def test_ties_resolve_as_the_dense_argmax(rng: np.random.Generator) -> None:
    # A regular polygon with rounded coordinates: many antipodal pairs at exactly one
    # distance; and repeated points. The first pair in row-major order wins, as before.
    for n in (80, 96, 200):
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        p = np.round(np.stack([10 * np.cos(t), 10 * np.sin(t), np.zeros(n)], -1), 1)
        assert tuple(map(int, farthest_pair(p))) == tuple(map(int, _dense(p)))
        q = np.repeat(p[: n // 4], 4, axis=0)
        assert tuple(map(int, farthest_pair(q))) == tuple(map(int, _dense(q)))
    cloud = rng.normal(size=(300, 3))
    assert tuple(map(int, farthest_pair(cloud))) == tuple(map(int, _dense(cloud)))


def test_batch_equals_loop_and_dense(rng: np.random.Generator) -> None:
    p = np.stack([_ring(rng, 120, s, 0.01) for s in (30.0, 200.0, 360.0, 90.0)]).reshape(
        2, 2, 120, 3
    )
    first, second = farthest_pair(p)
    want_first, want_second = _dense(p)
    assert first.shape == (2, 2)
    assert (first == want_first).all() and (second == want_second).all()


def test_no_n_by_n_array(rng: np.random.Generator) -> None:
    # 20,000 points: the N×N×3 array of differences would take 9.6 GB.
    import tracemalloc

    p = _ring(rng, 20_000, 200.0, 0.01)
    tracemalloc.start()
    try:
        farthest_pair(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6
