"""The compiled plain Newton-Raphson path (pipeline.kinematics.ik_compiled) against
the numpy iteration it stands in for, and batch = loop bit for bit."""

import numpy as np
import pytest

from pipeline.kinematics import ik, ik_compiled
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.jacobian import pose_and_jacobian
from pipeline.kinematics.transforms import differential_motion, transform_from_xyz_rpy
from pipeline.robots import get_robot
from pipeline.robots import puma560 as P
from tests.conftest import random_rigid
from tests.test_ik import LIM, RES, _design_start, _eps


def _kernel_pose_jacobian(chain: SerialChain, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = chain.n_joints
    T, J = np.empty((4, 4)), np.empty((6, n))
    ik_compiled._pose_jacobian(
        chain.base, chain.links, chain.tool, chain.joint_offsets, chain.prismatic, q, T, J
    )
    return T, J


def _stanford_signature(rng) -> SerialChain:
    """The Stanford arm (joint 3 prismatic) with every link moved by ~0.1 cm / 0.1°."""
    d = get_robot("stanford").design_chain()
    n = d.n_joints
    xyz, rpy = rng.normal(0.0, 0.1, (n, 3)), np.deg2rad(rng.normal(0.0, 0.1, (n, 3)))
    dL = transform_from_xyz_rpy(xyz, rpy)
    return SerialChain(d.links @ dL, d.prismatic, d.base, d.tool, d.joint_offsets)


@pytest.mark.parametrize("robot", ["puma", "stanford"])
def test_kernel_pose_jacobian_and_delta_match_numpy(rng, robot) -> None:
    chain = P.simulator_chain(_eps(rng)) if robot == "puma" else _stanford_signature(rng)
    assert chain.prismatic.any() == (robot == "stanford")
    lim = np.array([[-3.0, 3.0]] * 6)
    if robot == "stanford":
        lim[2] = (20.0, 60.0)  # cm
    q = rng.uniform(lim[:, 0], lim[:, 1], (50, 6))
    T_ref, J_ref = pose_and_jacobian(chain, q)
    targets = random_rigid(rng, 50)
    d_ref = differential_motion(T_ref, targets)
    for k in range(50):
        T, J = _kernel_pose_jacobian(chain, q[k])
        # Round-off of products of ~100 cm lengths: ~1e-13 cm; 1e-11 leaves room.
        np.testing.assert_allclose(T, T_ref[k], rtol=0, atol=1e-11)
        np.testing.assert_allclose(J, J_ref[k], rtol=0, atol=1e-11)
        d = np.empty(6)
        ik_compiled._delta(T_ref[k], targets[k], d)
        np.testing.assert_allclose(d, d_ref[k], rtol=0, atol=1e-12)


def test_kernel_lu_solve(rng) -> None:
    x, M = np.empty(6), np.empty((6, 7))
    for _ in range(20):
        A, b = rng.normal(size=(6, 6)), rng.normal(size=6)
        assert ik_compiled._lu_solve(A, b, x, M)
        np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-10, atol=1e-12)
    A[5] = 0.0  # exactly singular: the numpy iteration's SVD takes over
    assert not ik_compiled._lu_solve(A, b, x, M)


@pytest.fixture(scope="module")
def solved():
    """2,000 realistic targets plus 100 within model error of the wrist singularity,
    solved compiled and by numpy alone."""
    rng = np.random.default_rng(7)
    sig = P.simulator_chain(_eps(rng))
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (2100, 6))
    q[2000:, 4] = rng.normal(0.0, 1e-3, 100)  # θ5 ≈ 0
    T = forward_kinematics(sig, q)
    q0 = _design_start(T, P.branch_of(q))
    fast = ik.newton_raphson(sig, T, q0, RES)
    slow = ik.newton_raphson(sig, T, q0, RES, compiled=False)
    return sig, T, q0, fast, slow


def test_compiled_agrees_with_numpy(solved) -> None:
    _, _, _, fast, slow = solved
    # Every target numpy solves, the kernel solves; it may solve more (its
    # Levenberg-Marquardt steps: test_compiled_damped_steps_solve_more).
    assert not (slow.converged & ~fast.converged).any()
    # The same iteration; a count may differ where an error sits at a tolerance.
    assert (fast.iterations == slow.iterations).mean() >= 0.99
    ok = slow.converged
    assert ok.mean() >= 0.95
    # Both stop within 1e-7 cm / 1e-10 rad of the target: the solutions differ by
    # that much times the inverse Jacobian (~1e-9 rad), not by a different branch.
    np.testing.assert_allclose(fast.q[ok], slow.q[ok], rtol=0, atol=1e-7)
    assert fast.position_error_cm[ok].max() <= 1e-7
    assert fast.orientation_error_rad[ok].max() <= 1e-10


def test_compiled_damped_steps_solve_more(solved) -> None:
    """Regression (issue 18): targets within model error of the wrist singularity
    that the numpy safeguard gives up on (status unreachable or singular) are
    solved by the kernel's Levenberg-Marquardt steps from the same start."""
    _, _, _, fast, slow = solved
    gained = np.flatnonzero(fast.converged & ~slow.converged)
    assert gained.size >= 1
    assert fast.position_error_cm[gained].max() <= 1e-7
    assert fast.orientation_error_rad[gained].max() <= 1e-10
    assert fast.converged.sum() > slow.converged.sum()


def test_deferred_targets_are_the_numpy_solution(solved) -> None:
    sig, T, q0, fast, slow = solved
    rows = np.flatnonzero(fast.iterations != slow.iterations)
    rows = np.union1d(rows, np.flatnonzero(~fast.converged))
    assert rows.size  # the singular targets include some the kernel defers
    q, outcome, _, _ = ik_compiled.plain_newton(
        sig.base, sig.links, sig.tool, sig.joint_offsets, sig.prismatic, T, q0, RES,
        np.full(6, 0.5), 50, sig.length_scale, 1e-7, 1e-10,
    )  # fmt: skip
    deferred = np.flatnonzero(outcome == ik_compiled.FAST_DEFERRED)
    assert np.setdiff1d(np.flatnonzero(~fast.converged), deferred).size == 0
    # Deferred rows are solved by the numpy iteration from their start: same bits.
    np.testing.assert_array_equal(fast.q[deferred], slow.q[deferred])
    np.testing.assert_array_equal(fast.iterations[deferred], slow.iterations[deferred])
    for a, b in ((fast.position_error_cm, slow.position_error_cm), (fast.status, slow.status)):
        np.testing.assert_array_equal(a[deferred], b[deferred])


def test_batch_equals_loop_bit_for_bit(solved, monkeypatch) -> None:
    sig, T, q0, fast, _ = solved
    rows = np.r_[0:40, 2000:2040]  # regular and near-singular targets
    for k in rows:
        one = ik.newton_raphson(sig, T[k], q0[k], RES)
        np.testing.assert_array_equal(one.q[0], fast.q[k])
        assert one.iterations[0] == fast.iterations[k] and one.status[0] == fast.status[k]
        assert one.position_error_cm[0] == fast.position_error_cm[k]
    # The 2,100 ran on threads (above THREADED_MIN_TARGETS); on one thread: same bits.
    assert len(T) >= ik_compiled.THREADED_MIN_TARGETS
    monkeypatch.setattr(ik_compiled, "THREADED_MIN_TARGETS", 10**9)
    serial = ik.newton_raphson(sig, T, q0, RES)
    np.testing.assert_array_equal(serial.q, fast.q)
    np.testing.assert_array_equal(serial.iterations, fast.iterations)


def test_stanford_prismatic_joint_compiled(rng) -> None:
    sig = _stanford_signature(rng)
    q = rng.uniform([-2.5, -1.5, 25.0, -2.5, 0.3, -2.5], [2.5, 1.5, 55.0, 2.5, 1.5, 2.5], (300, 6))
    T = forward_kinematics(sig, q)
    q0 = q + rng.normal(0.0, [0.01, 0.01, 0.2, 0.01, 0.01, 0.01], q.shape)
    res = np.array([RES[0], RES[1], 0.001, RES[3], RES[4], RES[5]])  # 10 µm per count
    fast = ik.newton_raphson(sig, T, q0, res)
    slow = ik.newton_raphson(sig, T, q0, res, compiled=False)
    assert fast.converged.all() and slow.converged.all()
    np.testing.assert_allclose(fast.q, slow.q, rtol=0, atol=1e-7)
    np.testing.assert_allclose(fast.q, q, rtol=0, atol=1e-7)
    assert sig.prismatic[2]


def test_numpy_only_where_the_kernel_does_not_apply(rng) -> None:
    # History (Tables 5-1/5-2), task axes and robot batches take the numpy loop; the
    # same targets agree with the compiled path to the tolerance.
    sig = P.simulator_chain(_eps(rng))
    q = rng.uniform(LIM[:, 0], LIM[:, 1], (30, 6))
    T = forward_kinematics(sig, q)
    q0 = _design_start(T, P.branch_of(q))
    fast = ik.newton_raphson(sig, T, q0, RES)
    hist = ik.newton_raphson(sig, T, q0, RES, record_history=True)
    np.testing.assert_array_equal(hist.q, ik.newton_raphson(sig, T, q0, RES, compiled=False).q)
    np.testing.assert_allclose(hist.q, fast.q, rtol=0, atol=1e-7)
