"""Serial chain (5.1)-(5.3) and the geometric Jacobian."""

import numpy as np
import pytest

from pipeline.kinematics.chain import (
    SOA_BLOCK,
    SerialChain,
    forward_kinematics,
    frames_at,
    link_frames,
)
from pipeline.kinematics.dh import dh_link
from pipeline.kinematics.jacobian import geometric_jacobian
from pipeline.kinematics.transforms import rot_z, trans_z
from pipeline.robots import get_robot
from tests.conftest import random_rigid


def _random_chain(rng, prismatic):
    n = len(prismatic)
    return SerialChain(
        links=random_rigid(rng, n, scale=20.0),
        prismatic=np.array(prismatic),
        base=random_rigid(rng, 1)[0],
        tool=random_rigid(rng, 1)[0],
        joint_offsets=rng.normal(0, 0.3, n),
    )


def test_fk_is_product_of_5_2_5_3(rng) -> None:
    chain = _random_chain(rng, [False, True, False, True, False])
    q = rng.normal(size=5)
    T = chain.base
    for i in range(5):
        v = q[i] - chain.joint_offsets[i]
        motion = trans_z(v) if chain.prismatic[i] else rot_z(v)
        T = T @ motion @ chain.links[i]
    np.testing.assert_allclose(forward_kinematics(chain, q), T @ chain.tool, atol=1e-12)


def test_dh_chain_equals_product_of_links(rng) -> None:
    rob = get_robot("stanford")
    q = rng.uniform(0.0, 1.0, (50, 6)) + np.array([0, 0, 40.0, 0, 0, 0])
    T = forward_kinematics(rob.design_chain(), q)
    for k in range(50):
        M = np.eye(4)
        for i, j in enumerate(rob.joints):
            th = np.deg2rad(j.dh.theta_deg) + (0.0 if j.prismatic else q[k, i])
            d = j.dh.d_cm + (q[k, i] if j.prismatic else 0.0)
            M = M @ dh_link(th, d, j.dh.a_cm, np.deg2rad(j.dh.alpha_deg))
        np.testing.assert_allclose(T[k], M, atol=1e-10)


def test_link_frames_batch_equals_loop(rng) -> None:
    chain = _random_chain(rng, [False, False, True, False])
    q = rng.normal(size=(3, 7, 4))
    F = link_frames(chain, q)
    assert F.shape == (3, 7, 6, 4, 4)
    for idx in np.ndindex(3, 7):
        np.testing.assert_array_equal(F[idx], link_frames(chain, q[idx]))


def _finite_difference_jacobian(chain, q, h=1e-6):
    T0 = forward_kinematics(chain, q)
    J = np.zeros((6, len(q)))
    for i in range(len(q)):
        dq = np.zeros(len(q))
        dq[i] = h
        Tp, Tm = forward_kinematics(chain, q + dq), forward_kinematics(chain, q - dq)
        J[:3, i] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        dR = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T0[:3, :3].T  # skew(ω)
        J[3:, i] = [dR[2, 1], dR[0, 2], dR[1, 0]]
    return J


@pytest.mark.parametrize("robot", ["puma560", "stanford"])
def test_jacobian_matches_central_differences(robot, rng) -> None:
    rob = get_robot(robot)
    chain = rob.design_chain()
    lim = rob.limits.copy()
    lim[~rob.prismatic] = np.deg2rad(lim[~rob.prismatic])
    for _ in range(50):
        q = rng.uniform(lim[:, 0], lim[:, 1])
        J = geometric_jacobian(chain, q)
        # 1e-6: central differences with h = 1e-6 have truncation error ~h² · |T'''| ~ 1e-10
        # and rounding error ~eps · |T| / h ~ 1e-8 at 100 cm.
        np.testing.assert_allclose(J, _finite_difference_jacobian(chain, q), atol=1e-6)
    assert np.all(J[3:, 2] == 0.0) if robot == "stanford" else True


def test_jacobian_random_mixed_chain_and_batch(rng) -> None:
    chain = _random_chain(rng, [True, False, True, False, False, True])
    q = rng.normal(size=(10, 6))
    J = geometric_jacobian(chain, q)
    for k in range(10):
        np.testing.assert_allclose(J[k], _finite_difference_jacobian(chain, q[k]), atol=1e-6)
        np.testing.assert_array_equal(J[k], geometric_jacobian(chain, q[k]))


@pytest.mark.parametrize("prismatic", [[0, 0, 0, 0, 0, 0], [0, 1, 0, 1, 1, 0], [1, 1, 0, 0, 0, 1]])
def test_single_robot_fast_path_equals_general_path(rng, prismatic) -> None:
    """The column-major path for one robot (frames_soa) equals the per-pose products."""
    from pipeline.kinematics.jacobian import pose_and_jacobian

    chain = _random_chain(rng, prismatic)
    batched = SerialChain(  # a robot batch axis forces the general path
        links=chain.links[None],
        prismatic=chain.prismatic,
        base=chain.base,
        tool=chain.tool,
        joint_offsets=chain.joint_offsets,
    )
    q = rng.uniform(-3.0, 3.0, (4, 5, 6))
    # Round-off of a different summation order: ~1e-13 for these ~100 cm chains.
    np.testing.assert_allclose(link_frames(chain, q), link_frames(batched, q), atol=1e-11)
    np.testing.assert_allclose(
        forward_kinematics(chain, q), forward_kinematics(batched, q), atol=1e-11
    )
    T1, J1 = pose_and_jacobian(chain, q)
    T2, J2 = pose_and_jacobian(batched, q)
    np.testing.assert_allclose(T1, T2, atol=1e-11)
    np.testing.assert_allclose(J1, J2, atol=1e-11)
    assert T1.shape == (4, 5, 4, 4) and J1.shape == (4, 5, 6, 6)


def test_cross3_equals_numpy_cross(rng) -> None:
    from pipeline.kinematics.transforms import cross3

    a, b = rng.normal(size=(2, 3, 4, 3, 3))
    for axis in (-1, -2, -4):  # the axes of length 3
        np.testing.assert_array_equal(cross3(a, b, axis), np.cross(a, b, axis=axis))


@pytest.mark.parametrize("prismatic", [[0, 0, 0, 0, 0, 0], [0, 1, 0, 0, 1, 0]])
def test_one_pose_gives_the_same_bits_as_in_a_batch(rng, monkeypatch, prismatic) -> None:
    """One robot's poses take the column-major path at every batch size, in blocks:
    a pose alone, in a batch and across blocks gives identical results (the IK's
    batch-equals-loop property rests on this)."""
    import pipeline.kinematics.chain as chain_module
    from pipeline.kinematics.jacobian import pose_and_jacobian

    monkeypatch.setattr(chain_module, "SOA_BLOCK", 7)  # 30 poses: 5 blocks
    chain = _random_chain(rng, prismatic)
    q = rng.uniform(-3.0, 3.0, (30, 6))
    T, J = pose_and_jacobian(chain, q)
    F, T_fk = link_frames(chain, q), forward_kinematics(chain, q)
    for k in range(30):
        T1, J1 = pose_and_jacobian(chain, q[k])
        np.testing.assert_array_equal(T1, T[k])
        np.testing.assert_array_equal(J1, J[k])
        np.testing.assert_array_equal(link_frames(chain, q[k]), F[k])
        np.testing.assert_array_equal(forward_kinematics(chain, q[k]), T_fk[k])


@pytest.mark.parametrize("robot", ["puma560", "stanford"])
def test_frames_at_are_link_frames_rows_bit_for_bit(robot: str) -> None:
    """``frames_at``: each row's own frame of :func:`link_frames`, the same bits, over
    several blocks of rows (a part block at the end), any link or one for all."""
    chain = get_robot(robot).design_chain()
    rng = np.random.default_rng(3)
    K = 2 * SOA_BLOCK + 17
    q = rng.uniform(-2.0, 2.0, (K, chain.n_joints))
    link = rng.integers(0, chain.n_joints + 2, K)
    every = link_frames(chain, q)
    assert np.array_equal(frames_at(chain, q, link), every[np.arange(K), link])
    assert np.array_equal(frames_at(chain, q, chain.n_joints), every[:, chain.n_joints])
