"""Newton-Raphson on selected pose components (task axes) for arms with fewer than 6 joints.

Synthetic truth: the SCARA design chain with every link tilted by a small random
rotation (an identified signature's axes are not exactly parallel), targets
``F_s(q_true)`` whose orientation is replaced by "probe exactly down" (a tilt the
arm cannot reach), solved for position and rotation about Z only.
"""

import numpy as np
import pytest

from pipeline.control.controller import task_axes_for
from pipeline.errors import KinematicsError
from pipeline.kinematics import ik
from pipeline.kinematics.chain import SerialChain, chain_from_dh, forward_kinematics
from pipeline.kinematics.transforms import differential_motion, rot_x, rot_y, trans
from pipeline.robots import get_robot
from pipeline.units import joints_to_internal

SCARA = get_robot("scara")
RES = joints_to_internal(SCARA.encoder_resolution, SCARA.prismatic)
LIM = joints_to_internal(SCARA.limits.T, SCARA.prismatic).T
XYZ_RZ = (0, 1, 2, 5)
# The solver's own tolerances (1e-7 cm, 1e-10 rad) plus round-off.
POS_TOL_CM, ROT_TOL_RAD = 1e-7, 1e-10


def _tilted(rng) -> SerialChain:
    """SCARA design chain with links tilted by N(0, 0.05°) about X and Y, moved by 0.05 cm."""
    d = SCARA.design_chain()
    t = np.deg2rad(rng.normal(0.0, 0.05, (SCARA.n_joints, 2)))
    dp = rng.normal(0.0, 0.05, (SCARA.n_joints, 3))
    links = np.stack(
        [trans(*dp[i]) @ d.links[i] @ rot_x(t[i, 0]) @ rot_y(t[i, 1]) for i in range(len(t))]
    )
    return SerialChain(links, d.prismatic, d.base, d.tool @ trans(0, 0, 15.0), d.joint_offsets)


def _targets(rng, chain: SerialChain, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Targets (m, 4, 4) with the probe exactly down, and their true joints (m, 4).

    The elbow stays 20° from stretched (the SCARA's boundary singularity)."""
    q = rng.uniform(LIM[:, 0] * 0.9, LIM[:, 1] * 0.9, (m, 4))
    q[:, 1] = np.sign(q[:, 1]) * np.maximum(np.abs(q[:, 1]), np.deg2rad(20.0))
    q[:, 2] = rng.uniform(1.0, 29.0, m)
    T = forward_kinematics(chain, q)
    yaw = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    T[:, :3, :3] = 0.0
    T[:, 0, 0], T[:, 0, 1] = np.cos(yaw), np.sin(yaw)
    T[:, 1, 0], T[:, 1, 1] = np.sin(yaw), -np.cos(yaw)
    T[:, 2, 2] = -1.0  # tool Z straight down, X at the reached yaw
    return T, q


def test_scara_axes_are_position_and_yaw() -> None:
    assert task_axes_for(SCARA) == XYZ_RZ
    assert task_axes_for(get_robot("puma560")) == ik.ALL_AXES


def test_controllable_axes_of_a_planar_arm() -> None:
    planar = chain_from_dh(np.zeros(3), np.zeros(3), [30.0, 25.0, 10.0], np.zeros(3),
                           np.zeros(3, bool))  # fmt: skip
    q = np.random.default_rng(0).uniform(-2.0, 2.0, (8, 3))
    assert ik.controllable_axes(planar, q) == (0, 1, 5)


def test_scara_position_and_yaw_converge(rng) -> None:
    chain = _tilted(rng)
    T, q_true = _targets(rng, chain, 300)
    q0 = q_true + rng.normal(0.0, 0.02, q_true.shape)  # a design-inverse-like start
    res = ik.newton_raphson(chain, T, q0, RES, task_axes=XYZ_RZ)
    assert res.converged.all() and res.task_axes == XYZ_RZ
    d = differential_motion(forward_kinematics(chain, res.q), T)
    assert np.abs(d[:, :3]).max() <= POS_TOL_CM and np.abs(d[:, 5]).max() <= ROT_TOL_RAD
    assert res.position_error_cm.max() <= POS_TOL_CM
    np.testing.assert_allclose(res.orientation_error_rad, np.abs(d[:, 5]), atol=1e-15)
    # The tilt is not controlled: it stays (the links' tilts, ~1e-3 rad), and it is not zero.
    assert np.linalg.norm(d[:, 3:5], axis=1).min() > 1e-5
    # Position fixes shoulder, elbow and quill on the start's branch; the roll angle
    # differs from q_true by the tilt-yaw coupling (~1e-6 rad), which is not controlled.
    np.testing.assert_allclose(res.q[:, :3], q_true[:, :3], atol=1e-7)


def test_full_pose_is_unreachable_for_the_scara(rng) -> None:
    chain = _tilted(rng)
    T, q_true = _targets(rng, chain, 20)
    res = ik.newton_raphson(chain, T, q_true, RES)
    assert not res.converged.any()


def test_task_axes_batch_equals_loop(rng) -> None:
    chain = _tilted(rng)
    T, q_true = _targets(rng, chain, 12)
    q0 = q_true + rng.normal(0.0, 0.05, q_true.shape)
    batch = ik.newton_raphson(chain, T, q0, RES, task_axes=XYZ_RZ)
    for k in range(len(T)):
        one = ik.newton_raphson(chain, T[k], q0[k], RES, task_axes=XYZ_RZ)
        np.testing.assert_allclose(one.q[0], batch.q[k], atol=1e-12)
        assert one.status[0] == batch.status[k]


def test_all_six_axes_is_the_default(rng) -> None:
    puma = get_robot("puma560")
    d = puma.design_chain()
    lim = np.deg2rad(puma.limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (50, 6))
    T = forward_kinematics(d, q)
    q0 = q + rng.normal(0.0, 0.05, q.shape)
    res = np.deg2rad(puma.encoder_resolution)
    a = ik.newton_raphson(d, T, q0, res)
    b = ik.newton_raphson(d, T, q0, res, task_axes=(5, 4, 3, 2, 1, 0))
    assert np.array_equal(a.q, b.q) and np.array_equal(a.status, b.status)


def test_puma_position_only(rng) -> None:
    """Six joints, three task axes: minimum-norm steps, position exact, orientation free."""
    puma = get_robot("puma560")
    d = puma.design_chain()
    lim = np.deg2rad(puma.limits) * 0.8
    q = rng.uniform(lim[:, 0], lim[:, 1], (100, 6))
    T = forward_kinematics(d, q)
    q0 = q + rng.normal(0.0, 0.05, q.shape)
    res = ik.newton_raphson(d, T, q0, np.deg2rad(puma.encoder_resolution), task_axes=(0, 1, 2))
    assert res.converged.mean() >= 0.99
    ok = res.converged
    p = forward_kinematics(d, res.q[ok])[:, :3, 3]
    assert np.abs(p - T[ok, :3, 3]).max() <= POS_TOL_CM
    assert (res.orientation_error_rad == 0.0).all()  # no rotation component selected


@pytest.mark.parametrize("axes", [(), (0, 0, 1), (0, 6), (-1, 2)])
def test_bad_task_axes_raise(axes) -> None:
    d = SCARA.design_chain()
    with pytest.raises(KinematicsError, match="task axes"):
        ik.newton_raphson(d, np.eye(4), np.zeros(4), RES, task_axes=axes)
