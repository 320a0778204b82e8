"""Signature-control Monte-Carlo: the whole identification chain on batches of robots."""

from dataclasses import replace

import numpy as np
import pytest

from pipeline.evaluation.grid12 import INDEX_SIGNED
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.signature import frame_from_features
from pipeline.montecarlo import control as c
from pipeline.montecarlo import identification as ident
from pipeline.montecarlo.engine import run_study
from pipeline.montecarlo.features_study import run_features
from pipeline.montecarlo.stats import robot_seeds
from pipeline.montecarlo.studies import get_study
from pipeline.rig.atmosphere import _NODES, _WEIGHTS, Atmosphere
from pipeline.rig.digitizer import DigitizerModel, digitize
from pipeline.sensor.compensation import compensate
from pipeline.sensor.geometry import default_geometry, speed_of_sound_cm_s
from pipeline.stages.triangulate import robust_mean

EXACT = ident.SensorSetting(noise_factor=0.0, quantize=False)
SIGNED = np.array(INDEX_SIGNED)


def test_zero_noise_gives_zero_signature_error() -> None:
    v = c.signature_indices(EXACT, robot_seeds(0, "noise", 0, 3))
    # Exact ranges: compensation stops at 1e-9 cm, Newton-Raphson at 1e-7 cm / 1e-10 rad.
    assert v.shape == (3, 34)
    assert np.abs(v).max() < 1e-6


def test_reference_identification_reproduces_the_true_robot(rng: np.random.Generator) -> None:
    seeds = robot_seeds(1, "noise", 0, 2)
    rig = ident.rig_for(30, None, 0.0, 1)
    true = ident.true_chains(EXACT, seeds)
    ref = ident.identify(rig, ident.true_positions(rig, true))
    q = rng.uniform(-3.0, 3.0, (2, 20, 6))
    # Both models map the same readings to frames that differ by constant base/tool transforms.
    T_ref = np.stack([forward_kinematics(_robot(ref, r), q[r]) for r in range(2)])
    T_true = rig.sensor_from_base @ forward_kinematics(true, q)
    Y = np.linalg.inv(T_true[:, :1]) @ T_ref[:, :1]  # flange -> signature tool at one q
    np.testing.assert_allclose(T_true @ Y, T_ref, atol=1e-9)  # cm; exact up to round-off
    # The shortcut used for control: the same tool pose at q^s from joint n's sweep alone.
    T_qs = np.stack([forward_kinematics(_robot(ref, r), rig.q_signature) for r in range(2)])
    shortcut = ident.reference_tool_pose(rig, ident.true_positions(rig, true))
    np.testing.assert_allclose(shortcut, T_qs, atol=1e-9)


def _robot(chain, r):
    from pipeline.kinematics.chain import SerialChain

    return SerialChain(
        links=chain.links[r],
        prismatic=chain.prismatic,
        base=chain.base[r],
        tool=chain.tool[r],
        joint_offsets=chain.joint_offsets,
    )


def test_signature_batch_equals_loop() -> None:
    seeds = robot_seeds(2, "noise", 1, 3)
    setting = ident.SensorSetting(points=30, repeats=2)
    batch = c.signature_indices(setting, seeds)
    loop = np.concatenate([c.signature_indices(setting, [s]) for s in seeds])
    # Newton-Raphson's damping scale depends on the batch; converged poses agree to its tolerance.
    np.testing.assert_allclose(batch, loop, atol=1e-6)


def test_signature_error_is_linear_in_the_noise() -> None:
    seeds = robot_seeds(3, "noise", 0, 3)
    one = c.signature_indices(ident.SensorSetting(points=30, repeats=2, quantize=False), seeds)
    two = c.signature_indices(
        ident.SensorSetting(points=30, repeats=2, quantize=False, noise_factor=2.0), seeds
    )
    # Same deviates scaled by 2: first-order errors double; second order is ~σ/R ≈ 1e-3.
    scale = np.abs(one[:, SIGNED]).max()
    assert scale > 1e-4
    np.testing.assert_allclose(two[:, SIGNED], 2.0 * one[:, SIGNED], atol=0.02 * scale)


def test_misalignment_is_systematic() -> None:
    seeds = robot_seeds(4, "misalignment", 0, 3)
    zero = c.line3_errors(replace(EXACT, wac_error_cm=0.0), seeds)
    assert np.abs(zero).max() < 1e-6
    off = c.line3_errors(replace(EXACT, wac_error_cm=0.5), seeds)
    # A wrong W_AC distorts the measured space: every robot gets nearly the same error.
    assert np.abs(off[:, 0]).min() > 0.1
    assert off.std(axis=0).max() < 0.05 * np.abs(off).max()


def test_misalignment_reuses_each_robots_recording() -> None:
    seeds = robot_seeds(4, "misalignment", 0, 2)
    values = (-0.4, 0.6)
    together = c.misalignment_all(values, seeds)
    for k, w in enumerate(values):
        alone = c.line3_errors(ident.SensorSetting(wac_error_cm=w), seeds)
        np.testing.assert_allclose(together[k], alone, rtol=0, atol=1e-12)


def test_signature_studies_run_from_the_registry() -> None:
    for name in ("points", "radius", "misalignment"):
        st = get_study(name)
        small = replace(st, values=st.values[:1])
        res = run_study(small, robots=2, seed=0, progress=None)
        assert res.values.shape == (1, 2, len(st.index_names))
        assert np.isfinite(res.values).all()


def test_features_study_agrees_with_6_12_and_6_13() -> None:
    r = run_features(seed=0, trials=150, progress=None)
    big = r.points >= 50
    # 150 trials: the std is known to ~6 % (1σ); the formulas hold to ~5 % (docs).
    assert np.all(np.abs(r.sigma_delta_emp[big] / r.sigma_delta_612[big] - 1) < 0.3)
    assert np.all(np.abs(r.sigma_c_emp[big] / r.sigma_c_613[big] - 1) < 0.3)
    a, b = r.fit_612
    assert 0.0015 < a < 0.0035 and 0.15 < b < 0.5


# --------------------------------------------------- batching generalisations used above


def test_robust_mean_batch_equals_loop(rng: np.random.Generator) -> None:
    p = 50.0 + 0.01 * rng.standard_normal((40, 10, 3))
    p[::3, 4] += 0.5  # one spurious cycle in every third set
    mean, keep = robust_mean(p, 5.0, 0.005)
    for i in range(40):
        m1, k1 = robust_mean(p[i], 5.0, 0.005)
        np.testing.assert_array_equal(k1, keep[i])
        np.testing.assert_allclose(m1, mean[i], rtol=0, atol=1e-12)
    assert not keep[::3, 4].any() and keep[1::3].all()


def test_frame_from_features_batch_equals_loop(rng: np.random.Generator) -> None:
    a, o, t = rng.normal(size=(3, 25, 3)) * [[[1.0]], [[50.0]], [[50.0]]]
    batch = frame_from_features(a, o, t)
    loop = np.array([frame_from_features(a[i], o[i], t[i]) for i in range(25)])
    np.testing.assert_array_equal(batch, loop)


def test_compensate_batched_equals_flat(rng: np.random.Generator) -> None:
    g = default_geometry()
    target = rng.uniform([0.0, 30.0, 60.0], [120.0, 150.0, 150.0], (200, 3))
    raw = digitize(DigitizerModel(g), Atmosphere(), target, np.zeros(200), rng)
    flat = compensate(raw, g)
    batch = compensate(raw.reshape(4, 50, 5, 4), g)
    np.testing.assert_array_equal(batch.p_cm.reshape(200, 3), flat.p_cm)
    np.testing.assert_array_equal(batch.iterations.reshape(200), flat.iterations)


def test_digitize_takes_the_callers_deviates() -> None:
    g = default_geometry()
    target = np.array([[60.0, 80.0, 100.0], [20.0, 90.0, 120.0]])
    drawn = digitize(DigitizerModel(g), Atmosphere(), target, np.zeros(2), np.random.default_rng(5))
    z = np.random.default_rng(5).standard_normal((2, 5, 4))
    given = digitize(DigitizerModel(g), Atmosphere(), target, np.zeros(2), None, standard_normal=z)
    np.testing.assert_array_equal(drawn, given)


def test_still_air_flight_time_equals_the_quadrature(rng: np.random.Generator) -> None:
    atm = Atmosphere(mean_f=68.0, h_ref_cm=30.0)
    src, dst = rng.normal(size=(2, 50, 3)) * 100.0
    up = np.array([0.0, 1.0, 0.0])
    c_nodes = speed_of_sound_cm_s(np.full((50, len(_NODES)), 68.0))
    quad = np.linalg.norm(dst - src, axis=-1) * 0.5 * np.sum(_WEIGHTS / c_nodes, axis=-1)
    np.testing.assert_array_equal(atm.time_of_flight_s(src, dst, up, np.zeros(50)), quad)
    assert quad[0] == pytest.approx(np.linalg.norm(dst[0] - src[0]) / speed_of_sound_cm_s(68.0))
