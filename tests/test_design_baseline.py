"""The design-model baseline (issue 29): the design model with its base and tool point
registered to measured points, solved to its optimum."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.chain import link_frames
from pipeline.kinematics.transforms import rot_x, rot_z, trans
from pipeline.refine.baseline import register_design
from pipeline.refine.start import design_start
from pipeline.robots import get_robot

UR10 = "examples/ur10_ipa/ur10.toml"


def _points(seed: int = 0, m: int = 300):
    rng = np.random.default_rng(seed)
    robot = get_robot(UR10)
    chain = robot.design_chain()
    lim = np.radians(robot.limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (m, 6))
    B = trans(100.0, -50.0, 20.0) @ rot_z(0.7) @ rot_x(0.1)
    t = np.array([3.0, -2.0, 5.0])
    F = link_frames(chain, q)[:, 6]
    p = F[:, :3, :3] @ t + F[:, :3, 3]
    return chain, q, p @ B[:3, :3].T + B[:3, 3], B, t


def test_noiseless_points_register_exactly() -> None:
    chain, q, m, B, t = _points()
    b = register_design(chain, q, m, np.zeros(3))  # the tool point started 6.2 cm off
    assert b.errors_cm.max() < 1e-9
    np.testing.assert_allclose(b.tool, t, atol=1e-9)
    np.testing.assert_allclose(b.base, B, atol=1e-9)


def test_the_optimum_is_the_converged_alternation() -> None:
    """Gauss-Newton lands where the closed-form alternation ends when run to convergence."""
    chain, q, m, _, _ = _points(1)
    m = m + np.random.default_rng(2).normal(0.0, 0.05, m.shape)
    b = register_design(chain, q, m, np.zeros(3))
    slow = design_start(chain, q, m, np.zeros(3), q[0])  # START_ROUNDS only
    rms = float(np.sqrt(np.mean(b.errors_cm**2)))
    assert rms <= slow.rms_cm + 1e-12
    # stationary: moving the base by 1e-4 cm along any axis raises the RMS
    for d in np.vstack([np.eye(3), -np.eye(3)]) * 1e-4:
        e = b.errors(q, m - d)  # the same as the base translated by d
        assert np.sqrt(np.mean(e**2)) >= rms - 1e-12


def test_points_on_every_link_register_exactly() -> None:
    """Issue 41: the joint sweeps' targets sit on their links; the design with its base and
    one point per link registered to noiseless points of it gives them back exactly, from
    a base 2 cm and 3° off and every point at its link's origin."""
    from pipeline.refine.baseline import register_design_points

    rng = np.random.default_rng(5)
    robot = get_robot(UR10)
    chain = robot.design_chain()
    lim = np.radians(robot.limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (600, 6))
    link = np.repeat(np.arange(1, 7), 100)
    points = rng.uniform(-8.0, 8.0, (6, 3))
    B = trans(100.0, -50.0, 20.0) @ rot_z(0.7) @ rot_x(0.1)
    F = link_frames(chain, q)[np.arange(600), link]
    p = np.einsum("kij,kj->ki", F[:, :3, :3], points[link - 1]) + F[:, :3, 3]
    m = p @ B[:3, :3].T + B[:3, 3]
    start = trans(102.0, -50.0, 20.0) @ rot_z(0.75) @ rot_x(0.1)
    b = register_design_points(chain, q, m, link, link - 1, start)
    assert b.errors_cm.max() < 1e-9
    np.testing.assert_allclose(b.base, B, atol=1e-9)
    np.testing.assert_allclose(b.targets, points, atol=1e-9)
    np.testing.assert_allclose(b.errors(q, m, link, link - 1), b.errors_cm, atol=1e-12)
