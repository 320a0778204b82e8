"""S-Model (3.2)-(3.33) and D-H extraction (3.12)-(3.15)."""

import numpy as np
import pytest

from pipeline.kinematics.dh import dh_link
from pipeline.kinematics.smodel import dh_from_smodel, matrix_from_smodel, smodel_from_matrix
from pipeline.kinematics.transforms import rot_x, rot_z, trans_x, trans_z
from tests.conftest import random_rigid


def _params(p):
    return p.beta, p.d_bar, p.a_bar, p.alpha_bar, p.gamma, p.b


def test_expansion_3_3_equals_product_3_2(rng: np.random.Generator) -> None:
    be, al, ga = rng.uniform(-np.pi, np.pi, (3, 500))
    dd, aa, bb = rng.normal(0, 30, (3, 500))
    product = rot_z(be) @ trans_z(dd) @ trans_x(aa) @ rot_x(al) @ rot_z(ga) @ trans_z(bb)  # (3.2)
    np.testing.assert_allclose(matrix_from_smodel(be, dd, aa, al, ga, bb), product, atol=1e-12)


def test_dh_link_2_10_equals_product_2_9(rng: np.random.Generator) -> None:
    th, al = rng.uniform(-np.pi, np.pi, (2, 500))
    d, a = rng.normal(0, 30, (2, 500))
    np.testing.assert_allclose(
        dh_link(th, d, a, al), rot_z(th) @ trans_z(d) @ trans_x(a) @ rot_x(al), atol=1e-12
    )


def test_round_trip_random_rigid(rng: np.random.Generator) -> None:
    B = random_rigid(rng, 10_000)
    p = smodel_from_matrix(B)
    # 1e-10: tolerance of the issue; the reconstruction is exact to ~1e-13 at 50 cm scale.
    np.testing.assert_allclose(matrix_from_smodel(*_params(p)), B, atol=1e-10)


@pytest.mark.parametrize("case", ["parallel_same", "parallel_opposite", "intersecting_pure_rot"])
def test_round_trip_special_cases(case: str, rng: np.random.Generator) -> None:
    n = 200
    g = rng.uniform(-np.pi, np.pi, n)
    p = rng.normal(0, 40, (n, 3))
    if case == "parallel_same":  # a_x = a_y = 0, sin ᾱ = 0: b = 0 (3.32)
        B = rot_z(g)
    elif case == "parallel_opposite":  # ᾱ = π, also sin ᾱ = 0
        B = rot_x(np.pi) @ rot_z(g)
    else:
        B = rot_z(g) @ rot_x(rng.uniform(0.1, 3.0, n))
    B = B.copy()
    B[:, :3, 3] = p
    out = smodel_from_matrix(B)
    if case.startswith("parallel"):
        np.testing.assert_array_equal(out.b, 0.0)
        # β along the common normal, within (-π/2, π/2] (generalises (3.23)).
        assert np.all(np.abs(out.beta) <= np.pi / 2)
        np.testing.assert_allclose(np.tan(out.beta), p[:, 1] / p[:, 0], rtol=1e-9)
    np.testing.assert_allclose(matrix_from_smodel(*_params(out)), B, atol=1e-10)


def test_nearly_parallel_axes_give_huge_b(rng: np.random.Generator) -> None:
    # Axis tilted by 1e-5 rad with a 1 cm offset: the common normal is ~1e5 cm away
    # (the convergence-angle problem of Table 6-3), yet the matrix still round-trips.
    tilt = 1e-5
    B = rot_x(tilt) @ trans_z(0.0)
    B = B.copy()
    B[:3, 3] = [3.0, 1.0, 2.0]
    p = smodel_from_matrix(B)
    assert abs(p.b) > 1e4
    np.testing.assert_allclose(matrix_from_smodel(*_params(p)), B, atol=1e-10)


def test_parallel_axes_with_offset_on_x_give_beta_zero() -> None:
    B = rot_z(0.4).copy()
    B[:3, 3] = [-12.0, 0.0, 3.0]
    p = smodel_from_matrix(B)
    assert p.beta == 0.0  # Eq. (3.23)
    assert p.a_bar == pytest.approx(-12.0)


def test_b_sign_follows_errata() -> None:
    # Rot(x, 90°) then b = +5 along the new z: printed (3.32) sign would give -5.
    B = matrix_from_smodel(0.0, 0.0, 0.0, np.pi / 2, 0.0, 5.0)
    assert smodel_from_matrix(B).b == pytest.approx(5.0, abs=1e-12)


def test_batch_equals_loop(rng: np.random.Generator) -> None:
    B = random_rigid(rng, 50)
    batch = smodel_from_matrix(B)
    for k in range(50):
        one = smodel_from_matrix(B[k])
        for a, b in zip(_params(batch), _params(one), strict=True):
            assert a[k] == b


def test_dh_from_smodel_satisfies_3_8(rng: np.random.Generator) -> None:
    """(3.12)-(3.15): the extracted D-H links rebuild every B_i through (3.8)."""
    B = random_rigid(rng, 6)
    p = smodel_from_matrix(B)
    dh = dh_from_smodel(p)
    gamma_prev = np.r_[0.0, p.gamma[:-1]]
    b_prev = np.r_[0.0, p.b[:-1]]
    rebuilt = (
        rot_z(-gamma_prev)
        @ trans_z(-b_prev)
        @ dh_link(dh.theta, dh.d, dh.a, dh.alpha)
        @ rot_z(p.gamma)
        @ trans_z(p.b)
    )  # Eq. (3.8)
    np.testing.assert_allclose(rebuilt, B, atol=1e-10)


def test_dh_from_smodel_recovers_generating_dh(rng: np.random.Generator) -> None:
    """With twists in (-π, 0) the β rule of ERRATA picks the generating solution, not its twin."""
    n = 6
    th = rng.uniform(-np.pi, np.pi, n)
    al = rng.uniform(-3.0, -0.1, n)
    d, a = rng.normal(0, 30, (2, n))
    gamma = rng.uniform(-np.pi, np.pi, n)
    b = rng.normal(0, 10, n)
    gamma_prev = np.r_[0.0, gamma[:-1]]
    b_prev = np.r_[0.0, b[:-1]]
    B = rot_z(-gamma_prev) @ trans_z(-b_prev) @ dh_link(th, d, a, al) @ rot_z(gamma) @ trans_z(b)
    dh = dh_from_smodel(smodel_from_matrix(B))
    np.testing.assert_allclose(np.angle(np.exp(1j * (dh.theta - th))), 0, atol=1e-9)
    np.testing.assert_allclose(dh.d, d, atol=1e-9)
    np.testing.assert_allclose(dh.a, a, atol=1e-9)
    np.testing.assert_allclose(dh.alpha, al, atol=1e-9)
