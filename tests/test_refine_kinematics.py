"""The refinement's kinematic model against the signature chain's forward kinematics."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.signature import signature_chain
from pipeline.kinematics.transforms import rot_x, rot_y, rot_z, trans
from pipeline.refine.kinematics import ChainModel, start_points
from pipeline.refine.motions import vee


def _random_frames(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.uniform(-np.pi, np.pi, (n, 3))
    t = trans(*rng.uniform(-50.0, 50.0, (3, n)))
    return t @ rot_z(a[:, 0]) @ rot_y(a[:, 1]) @ rot_x(a[:, 2])


def _model(rng: np.random.Generator, prismatic: list[bool], k: int = 40) -> ChainModel:
    """Observations of a point on every link and of the tool, at random readings."""
    n = len(prismatic)
    link = np.r_[rng.integers(1, n + 1, k), np.full(k, n)]
    point = np.r_[link[:k] - 1, np.full(k, n)]  # point j-1 on link j, point n the tool
    return ChainModel(
        frames0=_random_frames(rng, n),
        prismatic=np.array(prismatic),
        link=link,
        theta=rng.uniform(-1.5, 1.5, (2 * k, n)),
        point=point,
        point_names=tuple([f"sweep{j}/t" for j in range(1, n + 1)] + ["tool"]),
    )


CASES = [[False] * 6, [False, False, True, False], [False, True]]


@pytest.mark.parametrize("prismatic", CASES)
def test_positions_are_the_signature_chain_forward_kinematics(prismatic: list[bool]) -> None:
    """A point on link ℓ moves as the signature chain truncated after joint ℓ (4.51): its
    local coordinates in S̄_ℓ are constant; the tool point as the full chain's tool."""
    rng = np.random.default_rng(1)
    m = _model(rng, prismatic)
    n = m.n_joints
    x = rng.normal(0.0, 0.05, m.n_params)
    x[m.n_axis_params :] = rng.uniform(-80.0, 80.0, 3 * m.n_points)
    F = m.signature_frames(x, tool_point=n)  # S̄_0 … S̄_n, tool
    q_sig = rng.uniform(-1.0, 1.0, n)
    q = m.theta + q_sig
    p = m.positions(x)
    for j in range(m.n_points):
        sel = m.point == j
        ell = n if j == n else j + 1
        chain = signature_chain(F[: ell + 1], q_sig[:ell], m.prismatic[:ell])
        p0 = x[m.point_slice(j)]
        local = np.linalg.solve(F[ell], np.r_[p0, 1.0])  # the point in S̄_ℓ at q̄^s
        want = (forward_kinematics(chain, q[sel][:, :ell]) @ local)[:, :3]
        np.testing.assert_allclose(p[sel], want, atol=1e-9)
    tool = signature_chain(F[: n + 1], q_sig, m.prismatic, F[n + 1])
    sel = m.point == n
    np.testing.assert_allclose(p[sel], forward_kinematics(tool, q[sel])[:, :3, 3], atol=1e-9)


@pytest.mark.parametrize("prismatic", CASES)
def test_jacobians_match_central_differences(prismatic: list[bool]) -> None:
    rng = np.random.default_rng(2)
    m = _model(rng, prismatic)
    n = m.n_joints
    x = rng.normal(0.0, 0.05, m.n_params)
    x[m.n_axis_params :] = rng.uniform(-80.0, 80.0, 3 * m.n_points)
    q_sig = np.zeros(n)

    def rotation(x: np.ndarray) -> np.ndarray:
        F = m.signature_frames(x, tool_point=n)
        chain = signature_chain(F[: n + 1], q_sig, m.prismatic, F[n + 1])
        return forward_kinematics(chain, m.theta)[:, :3, :3]

    _, W = _assert_central_differences(m, x, rotation)
    assert np.abs(W[m.link == n]).max() > 0.1  # the tool rows are not all zero


def _assert_central_differences(m, x: np.ndarray, rotation) -> tuple[np.ndarray, np.ndarray]:
    """``m``'s position and tool-orientation Jacobians at ``x`` against central differences
    of its positions and of ``rotation(x)`` (the tool rows' rotations); returns (J, W)."""
    n = m.n_joints
    J, W = m.position_jacobian(x), m.tool_orientation_jacobian(x)
    R = rotation(x)
    h = 1e-6
    for i in range(m.n_params):
        e = np.zeros(m.n_params)
        e[i] = h
        dp = (m.positions(x + e) - m.positions(x - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, i], dp, atol=1e-6 * (1 + np.abs(dp).max()))
        dR = (rotation(x + e) - rotation(x - e)) / (2 * h)
        w = vee(dR @ np.swapaxes(R, 1, 2))
        w[m.link != n] = 0.0
        np.testing.assert_allclose(W[:, :, i], w, atol=1e-7)
    return J, W


def test_start_points_invert_the_start_chain_and_skip_missing() -> None:
    rng = np.random.default_rng(3)
    m = _model(rng, [False] * 6)
    x = np.zeros(m.n_params)
    x[m.n_axis_params :] = rng.uniform(-80.0, 80.0, 3 * m.n_points)
    p = m.positions(x)
    p[::7] = np.nan
    np.testing.assert_allclose(start_points(m, p).ravel(), x[m.n_axis_params :], atol=1e-10)


def test_zero_moves_give_the_start_frames_exactly() -> None:
    m = _model(np.random.default_rng(4), [False, True, False])
    np.testing.assert_array_equal(m.frames(np.zeros(m.n_params)), m.frames0)
    assert m.n_axis_params == 4 + 2 + 4
    assert m.param_names[4:6] == ("joint2.rx", "joint2.ry")
    assert len(m.param_names) == len(m.param_units) == m.n_params


@pytest.mark.parametrize("prismatic", CASES)
def test_nongeometric_terms_move_the_joints_and_their_jacobian_matches(
    prismatic: list[bool],
) -> None:
    """With terms, the positions are the rigid model's at θ + Φβ, and the columns of β
    (position and tool orientation) match central differences (issue 27)."""
    from dataclasses import replace

    from pipeline.kinematics.nongeometric import Terms

    rng = np.random.default_rng(5)
    rigid = _model(rng, prismatic)
    n = rigid.n_joints
    terms = Terms(compliance=((1, 2), (2, 2)), harmonic=((1, "cos"), (1, "sin"), (n, "sin")))
    Phi = rng.normal(0.0, 1.0, (len(rigid.link), n, terms.size))
    m = replace(rigid, terms=terms)
    m.__dict__["regressor"] = Phi  # a random regressor: the model is linear in it
    assert m.n_params == rigid.n_params + terms.size
    assert m.param_names[-terms.size :] == terms.names
    x = rng.normal(0.0, 0.05, m.n_params)
    x[m.n_axis_params : m.beta_slice.start] = rng.uniform(-80.0, 80.0, 3 * m.n_points)
    beta = x[m.beta_slice]
    moved = replace(rigid, theta=rigid.theta + Phi @ beta)
    np.testing.assert_allclose(m.positions(x), moved.positions(x[: rigid.n_params]), atol=1e-12)
    np.testing.assert_allclose(
        m.tool_rotations(x), moved.tool_rotations(x[: rigid.n_params]), atol=1e-14
    )
    J, _ = _assert_central_differences(m, x, m.tool_rotations)
    assert np.abs(J[:, :, m.beta_slice]).max() > 1.0
