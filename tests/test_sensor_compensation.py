"""Slant range compensation (Appendix E) against an exactly linear-speed atmosphere."""

from decimal import Decimal, localcontext

import numpy as np
import pytest

from pipeline.errors import ArmsigError
from pipeline.sensor.compensation import (
    compensate,
    line_of_sight_length,
    rod_ratios,
    speed_ratio_at_height,
)
from pipeline.sensor.geometry import DigitizerGeometry, default_geometry, speed_of_sound_cm_s
from pipeline.sensor.triangulation import triangulate

GEOM = default_geometry()
S_STAR = GEOM.nominal_speed_cm_s


def linear_air(mean_f: float, delta_f: float) -> tuple[float, float]:
    """``β(h) = β0 + g·h``: ``mean_f`` at h = 0 (mic C), ``delta_f`` more 150 cm higher."""
    beta0 = float(speed_of_sound_cm_s(mean_f))
    return beta0, (float(speed_of_sound_cm_s(mean_f + delta_f)) - beta0) / 150.0


def time_of_flight(src, dst, beta0: float, g: float, geom: DigitizerGeometry = GEOM):
    """ERRATA law ``t = L ln(βm/βt)/(βm − βt)`` (``L/β`` if equal), written in log1p form."""
    length = np.linalg.norm(dst - src, axis=-1)
    b_t, b_m = beta0 + g * geom.height(src), beta0 + g * geom.height(dst)
    d = (b_m - b_t) / b_t
    safe = np.where(d == 0.0, 1.0, d)
    return np.where(d == 0.0, length / b_t, length * np.log1p(safe) / (safe * b_t))


def digitize(targets: np.ndarray, beta0: float, g: float) -> np.ndarray:
    """Noiseless raw ranges (M, 5, 4): sparkers 1-4 on the rods, 5 = target."""
    sparks = np.concatenate(
        [np.broadcast_to(GEOM.rod_sparkers, (len(targets), 4, 3)), targets[:, None, :]], axis=1
    )
    return S_STAR * time_of_flight(sparks[:, :, None, :], GEOM.microphones, beta0, g)


def random_targets(rng: np.random.Generator, n: int) -> np.ndarray:
    out = np.empty((0, 3))
    while len(out) < n:
        p = rng.uniform([-50.0, -60.0, 20.0], [200.0, 200.0, 200.0], size=(4 * n, 3))
        s = np.linalg.norm(p[:, None, :] - GEOM.microphones[:3], axis=-1)
        out = np.vstack([out, p[np.all((s >= 30.0) & (s <= 250.0), axis=-1)]])
    return out[:n]


def test_forward_model_is_the_linear_speed_integral(rng: np.random.Generator) -> None:
    beta0, g = linear_air(68.0, 2.0)
    src, dst = random_targets(rng, 50), GEOM.microphones[0]
    nodes, weights = np.polynomial.legendre.leggauss(20)
    u = 0.5 * (nodes + 1.0)
    pts = src[:, None, :] + u[:, None] * (dst - src)[:, None, :]
    quad = (
        np.linalg.norm(dst - src, axis=-1) * 0.5 * np.sum(weights / (beta0 + g * pts @ GEOM.up), -1)
    )
    np.testing.assert_allclose(time_of_flight(src, dst, beta0, g), quad, rtol=1e-13)


def test_rod_ratios_recover_speed_ratio() -> None:
    for temp in (62.0, 70.0, 77.5):
        c = float(speed_of_sound_cm_s(temp))
        raw = (
            S_STAR * np.linalg.norm(GEOM.rod_sparkers - GEOM.microphones[[1, 1, 3, 3]], axis=-1) / c
        )
        f_b, f_d = rod_ratios(raw[:2], raw[2:], GEOM.rod_length_cm)
        np.testing.assert_allclose([f_b, f_d], c / S_STAR, rtol=1e-14)
    f_b, f_d = rod_ratios(np.array([[40.0, np.nan]]), np.array([[40.0, 140.0]]), 100.0)
    assert np.isnan(f_b[0]) and f_d[0] == 1.0
    with pytest.raises(ArmsigError, match="shape"):
        rod_ratios(np.ones(3), np.ones(2), 100.0)


def test_speed_ratio_is_the_line_through_the_rods() -> None:
    h = np.linspace(-200.0, 300.0, 11)
    f = speed_ratio_at_height(h, 1.002, 0.999, 100.0, -40.0)
    np.testing.assert_allclose(f, 1.002 + (h - 100.0) * (0.999 - 1.002) / -140.0, rtol=1e-15)
    assert speed_ratio_at_height(100.0, 1.002, 0.999, 100.0, -40.0) == 1.002
    assert speed_ratio_at_height(-40.0, 1.002, 0.999, 100.0, -40.0) == 0.999
    with pytest.raises(ArmsigError, match="same height"):
        speed_ratio_at_height(h, 1.0, 1.0, 5.0, 5.0)


def raw_ref(length: float, f_m: float, f_t: float) -> float:
    """``s_raw = S*·t`` from the ERRATA law, in 50-digit decimal arithmetic."""
    with localcontext() as ctx:
        ctx.prec = 50
        L, m, t = Decimal(length), Decimal(f_m), Decimal(f_t)
        return float(L / t if m == t else L * (m / t).ln() / (m - t))


def test_line_of_sight_length_inverts_the_forward_law(rng: np.random.Generator) -> None:
    f_m = rng.uniform(0.97, 1.03, 300)
    ulp = np.finfo(float).eps
    rel = np.concatenate(
        [
            rng.uniform(-0.01, 0.01, 100),  # up to ~6 °F apart
            np.zeros(50),  # level line of sight
            rng.integers(-64, 65, 100) * ulp,  # a few ulps apart
            rng.choice([-1.0, 1.0], 50) * 10.0 ** rng.uniform(-12, -6, 50),  # nearly level
        ]
    )
    f_t = f_m * (1.0 + rel)
    length = rng.uniform(30.0, 250.0, 300)
    s_raw = np.array([raw_ref(*a) for a in zip(length, f_m, f_t, strict=True)])
    out = line_of_sight_length(s_raw, f_m, f_t)
    np.testing.assert_allclose(out, length, rtol=1e-12)  # measured ≲ 3e-16
    equal = f_m == f_t
    assert equal.sum() >= 50
    np.testing.assert_array_equal(out[equal], s_raw[equal] * f_m[equal])
    assert line_of_sight_length(np.ones((4, 3)), np.ones((4, 3)), np.ones((4, 1))).shape == (4, 3)


@pytest.mark.parametrize("mean_f, delta_f", [(70.0, 2.0), (66.0, -2.0), (74.5, 1.2)])
def test_compensate_recovers_targets(rng, mean_f: float, delta_f: float) -> None:
    targets = random_targets(rng, 400)
    raw = digitize(targets, *linear_air(mean_f, delta_f))
    res = compensate(raw, GEOM)
    assert res.valid.all() and res.converged.all()
    assert res.iterations.max() <= 6  # measured 4-5: contraction ~1e-3 per step
    err = np.linalg.norm(res.p_cm - targets, axis=-1)
    assert err.max() < 1e-9  # measured ~1e-12 cm
    true_s = np.linalg.norm(targets[:, None, :] - GEOM.microphones[:3], axis=-1)
    np.testing.assert_allclose(res.s_abc_cm, true_s, rtol=1e-13)
    # the iteration matters: f_avg alone leaves a visible error
    first = triangulate(((res.f_b + res.f_d) / 2)[:, None] * raw[:, 4, :3], 143.0, 143.0, 203.0)
    assert np.linalg.norm(first - targets, axis=-1).max() > 0.1  # measured ~1 cm


def test_uniform_temperature_is_exact_in_one_step(rng: np.random.Generator) -> None:
    targets = random_targets(rng, 200)
    beta0, g = linear_air(66.0, 0.0)
    assert g == 0.0
    res = compensate(digitize(targets, beta0, g), GEOM)
    np.testing.assert_allclose(res.f_b, beta0 / S_STAR, rtol=1e-14)
    np.testing.assert_allclose(res.f_d, beta0 / S_STAR, rtol=1e-14)
    assert (res.iterations == 1).all() and res.converged.all()
    assert np.abs(res.p_cm - targets).max() < 1e-9


def test_missing_echoes_invalidate_only_their_cycle(rng: np.random.Generator) -> None:
    targets = random_targets(rng, 6)
    raw = digitize(targets, *linear_air(70.0, 1.5))
    raw[0, 0, 1] = np.nan  # sparker 1 -> B (upper rod)
    raw[1, 3, 3] = np.nan  # sparker 4 -> D (lower rod)
    raw[2, 4, 2] = np.nan  # target -> C
    raw[3, 4, :3] = 10.0  # target echoes that no point can produce
    raw[4, 4, 3] = raw[4, 0, 0] = np.nan  # echoes the algorithm does not use
    res = compensate(raw, GEOM)
    np.testing.assert_array_equal(res.valid, [False, False, False, False, True, True])
    assert np.isnan(res.p_cm[:4]).all() and np.isnan(res.s_abc_cm[:4]).all()
    assert not res.converged[:4].any() and (res.iterations[:4] == 0).all()
    assert np.isnan(res.f_b[0]) and np.isnan(res.f_d[1]) and np.isfinite(res.f_b[1])
    assert np.abs(res.p_cm[4:] - targets[4:]).max() < 1e-9


def test_batch_shapes_and_loop(rng: np.random.Generator) -> None:
    targets = random_targets(rng, 12)
    raw = digitize(targets, *linear_air(71.0, -1.0))
    batch = compensate(raw.reshape(3, 4, 5, 4), GEOM)
    assert batch.p_cm.shape == (3, 4, 3) and batch.iterations.shape == (3, 4)
    for k, one in enumerate(compensate(r, GEOM) for r in raw):
        assert one.p_cm.shape == (3,) and bool(one.valid)
        np.testing.assert_array_equal(one.p_cm, batch.p_cm.reshape(12, 3)[k])
        assert int(one.iterations) == batch.iterations.reshape(12)[k]
    with pytest.raises(ArmsigError, match="shape"):
        compensate(np.ones((2, 4, 5)), GEOM)


def test_w_ac_calibration_error_propagates(rng: np.random.Generator) -> None:
    targets = random_targets(rng, 200)
    raw = digitize(targets, *linear_air(70.0, 2.0))
    res = compensate(raw, default_geometry(w_ac=GEOM.w_ac + 1.0))
    assert res.valid.all()
    err = np.linalg.norm(res.p_cm - targets, axis=-1)
    assert err.max() > 0.1  # Section 7.3: a 1 cm misalignment is a cm-level error
