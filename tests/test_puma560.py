"""Puma 560: model (7.1), Appendix B forward and closed-form inverse."""

import numpy as np
import pytest

from pipeline.kinematics.chain import chain_from_dh, forward_kinematics
from pipeline.kinematics.transforms import pose_error
from pipeline.robots import get_robot
from pipeline.robots import puma560 as P


@pytest.fixture(scope="module")
def puma():
    return get_robot("puma560")


def _random_q(rng, robot, n):
    lim = np.deg2rad(robot.limits)
    return rng.uniform(lim[:, 0], lim[:, 1], (n, 6))


def test_model_7_1_at_zero_error_equals_design_dh(puma, rng) -> None:
    q = rng.uniform(-np.pi, np.pi, (1000, 6))
    T_dh = forward_kinematics(puma.design_chain(), q)
    T_sim = forward_kinematics(P.simulator_chain(), q)
    np.testing.assert_allclose(T_sim, T_dh, atol=1e-9)  # ERRATA: equal to 1e-13 in fact


def test_appendix_b_matches_table_6_2(rng) -> None:
    t = P.TABLE_6_2
    chain = chain_from_dh(
        np.zeros(6), t["d_cm"], t["a_cm"], np.deg2rad(t["alpha_deg"]), np.zeros(6, bool)
    )
    q = rng.uniform(-np.pi, np.pi, (1000, 6))
    T_b = P.fk_appendix_b(q, d3=14.909, a2=43.18, a3=-2.032, d4=43.307)
    np.testing.assert_allclose(forward_kinematics(chain, q), T_b, atol=1e-9)


def test_table_6_2_differs_from_design_in_documented_entries(puma) -> None:
    design_d = [j.dh.d_cm for j in puma.joints]
    differ = [i for i in range(6) if design_d[i] != P.TABLE_6_2["d_cm"][i]]
    assert differ == [0, 3, 5]  # d1: frame 0 on the mounting surface; d4; d6 (flange)
    assert [j.dh.a_cm for j in puma.joints] == list(P.TABLE_6_2["a_cm"])
    assert [j.dh.alpha_deg for j in puma.joints] == list(P.TABLE_6_2["alpha_deg"])


def test_simulator_chain_batches_over_robots(rng) -> None:
    eps = rng.normal(0, 0.01, (4, 39))
    q = rng.uniform(-1, 1, (4, 6))
    batch = forward_kinematics(P.simulator_chain(eps), q)
    loop = np.array([forward_kinematics(P.simulator_chain(eps[k]), q[k]) for k in range(4)])
    np.testing.assert_allclose(batch, loop, atol=1e-12)


def test_error_categories_partition_39() -> None:
    all_idx = sorted(P.EPS_ENCODER + P.EPS_POSITIONAL + P.EPS_ORIENTATIONAL)
    assert all_idx == list(range(1, 40))


def test_encoder_errors_act_as_joint_offsets(rng) -> None:
    # ε8 ends K0 with Rot(z, ε8): the same as reading joint 1 ε8 too high.
    eps = np.zeros(39)
    eps[7] = 0.01
    q = rng.uniform(-1, 1, 6)
    q_shift = q.copy()
    q_shift[0] += 0.01
    np.testing.assert_allclose(
        forward_kinematics(P.simulator_chain(eps), q),
        forward_kinematics(P.simulator_chain(), q_shift),
        atol=1e-12,
    )


def test_ik_round_trip_all_branches(puma, rng) -> None:
    chain = puma.design_chain()
    q = _random_q(rng, puma, 10_000)
    T = forward_kinematics(chain, q)
    sols, ok = P.inverse_kinematics(T)
    assert ok.all()  # every branch of a reachable pose is reachable for the Puma geometry
    T_sol = forward_kinematics(chain, np.where(ok[..., None], sols, 0.0))
    dp, dth = pose_error(T[:, None], T_sol)
    assert dp[ok].max() < 1e-8  # cm
    assert dth[ok].max() < 1e-9  # rad
    # The branch containing the original configuration returns it.
    flags = P.branch_of(q)
    idx = np.array([P.BRANCHES.index(P.Branch(*f)) for f in flags])
    q_back = sols[np.arange(len(q)), idx]
    np.testing.assert_allclose(P.wrap_angle(q_back - q), 0.0, atol=1e-9)
    # All eight branches are distinct solutions.
    assert np.all(np.ptp(sols[..., 2], axis=-1) > 0)


def test_ik_with_tool_and_base(puma, rng) -> None:
    from pipeline.kinematics.transforms import transform_from_xyz_rpy

    tool = transform_from_xyz_rpy([1.0, 2.0, 15.0], [0.1, -0.2, 0.3])
    base = transform_from_xyz_rpy([10.0, -5.0, 2.0], [0.0, 0.0, 0.5])
    chain = puma.design_chain()
    q = _random_q(rng, puma, 200)
    T = base @ forward_kinematics(chain, q) @ tool
    sols, ok = P.inverse_kinematics(T, tool=tool, base=base)
    T_sol = base @ forward_kinematics(chain, np.nan_to_num(sols)) @ tool
    dp, dth = pose_error(T[:, None], T_sol)
    assert dp[ok].max() < 1e-8 and dth[ok].max() < 1e-9


def test_ik_wrist_singularity(puma, rng) -> None:
    chain = puma.design_chain()
    q = _random_q(rng, puma, 100)
    q[:, 4] = 0.0
    T = forward_kinematics(chain, q)
    sols, ok = P.inverse_kinematics(T, q4_singular=0.3)
    assert ok.all() and np.isfinite(sols).all()
    T_sol = forward_kinematics(chain, sols)
    dp, dth = pose_error(T[:, None], T_sol)
    assert dp.max() < 1e-8 and dth.max() < 1e-9
    # On the original arm branch the wrist is singular: θ4 takes the documented choice.
    flags = P.branch_of(q)
    for w in (1, -1):
        idx = np.array([P.BRANCHES.index(P.Branch(f[0], f[1], w)) for f in flags])
        np.testing.assert_allclose(sols[np.arange(100), idx, 3], 0.3)
        np.testing.assert_allclose(sols[np.arange(100), idx, 4], 0.0, atol=1e-9)


def test_ik_unreachable_pose_is_flagged(puma) -> None:
    T = np.eye(4)
    T[:3, 3] = [500.0, 0.0, 0.0]
    sols, ok = P.inverse_kinematics(T)
    assert not ok.any() and np.isnan(sols).all()


def test_ik_batch_equals_loop(puma, rng) -> None:
    T = forward_kinematics(puma.design_chain(), _random_q(rng, puma, 20))
    sols, ok = P.inverse_kinematics(T)
    for k in range(20):
        s1, o1 = P.inverse_kinematics(T[k])
        np.testing.assert_array_equal(s1, sols[k])
        np.testing.assert_array_equal(o1, ok[k])
