"""Signature-based control of an identified session (Chapter 5)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.control.controller import Controller, parse_branch
from pipeline.control.limits import outside_mask
from pipeline.control.session import session_controller
from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.ik import STATUS_OUT_OF_LIMITS
from pipeline.kinematics.transforms import invert_transform
from pipeline.robots import puma560

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def robot3(robot3_identified: Path) -> Controller:
    return session_controller(robot3_identified)


def _targets(c: Controller, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lim = np.deg2rad(c.robot.limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, 6))
    return q, invert_transform(c.sensor_from_base) @ forward_kinematics(c.signature.chain, q)


@pytest.mark.parametrize("method", ["nr", "jacobi"])
def test_solves_on_the_requested_branch(robot3: Controller, method: str) -> None:
    q, T = _targets(robot3, 2000, 5)
    flags = puma560.branch_of(q)
    good = 0
    for b in puma560.BRANCHES:
        sel = np.all(flags == [b.shoulder, b.elbow, b.wrist], axis=1)
        r = robot3.solve(T[sel], branch=b, method=method)
        on_branch = np.all(puma560.branch_of(r.q) == [b.shoulder, b.elbow, b.wrist], axis=1)
        ok = (
            r.converged
            & (r.position_error_cm <= 1e-6)
            & (np.degrees(r.orientation_error_rad) <= 1e-7)
        )
        good += int((ok & on_branch).sum())
        assert np.isfinite(r.q).all()
    # Issue 5's acceptance for both methods: >= 99.9 % (10,000 robot3 targets,
    # seeds 5 and 11: NR 99.93 / 99.92 %, Jacobi 99.97 / 99.98 %).
    assert good / len(q) >= 0.999


def test_batch_equals_loop(robot3: Controller) -> None:
    q, T = _targets(robot3, 8, 6)
    b = parse_branch("right-up-noflip")
    batch = robot3.solve(T, branch=b)
    for k in range(8):
        one = robot3.solve(T[k], branch=b)
        np.testing.assert_array_equal(one.q[0], batch.q[k])


def test_design_alignment_is_recorded(robot3: Controller) -> None:
    # Design base frame -> sensor: the rig puts the Puma base about 88 cm in front of the wall.
    assert 50.0 < robot3.sensor_from_base[2, 3] < 130.0
    np.testing.assert_allclose(
        robot3.sensor_from_base[:3, :3].T @ robot3.sensor_from_base[:3, :3], np.eye(3), atol=1e-12
    )


def test_bad_branch_and_method(robot3: Controller) -> None:
    with pytest.raises(ArmsigError, match="unknown branch"):
        parse_branch("sideways")
    with pytest.raises(ArmsigError, match="unknown method"):
        robot3.solve(np.eye(4), method="magic")


def test_cli_ik_pose_batch_and_convergence(robot3: Controller, tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.ipc as ipc
    from typer.testing import CliRunner

    from pipeline.cli import app
    from pipeline.control.convergence import convergence_tables

    d = tmp_path / "s"
    d.mkdir()
    shutil.copy(ROOT / "sessions/robot3/recording.mcap", d)
    identify(d, report=False)
    runner = CliRunner()
    r = runner.invoke(app, ["ik", str(d), "--pose", "40", "20", "60", "180", "0", "90"])
    assert r.exit_code == 0 and "converged" in r.output
    t = pa.table(
        {
            k: [v]
            for k, v in zip(
                ("x_cm", "y_cm", "z_cm", "rx_deg", "ry_deg", "rz_deg"),
                (40.0, 20.0, 60.0, 180.0, 0.0, 90.0),
                strict=True,
            )
        }
    )
    with ipc.new_file(str(tmp_path / "t.arrow"), t.schema) as w:
        w.write_table(t)
    r = runner.invoke(
        app,
        ["ik", str(d), "--targets", str(tmp_path / "t.arrow"), "--out", str(tmp_path / "q.arrow")],
    )
    assert r.exit_code == 0 and "1 of 1 targets converged" in r.output
    import polars as pl

    out = pl.read_ipc(tmp_path / "q.arrow")
    assert out["status"][0] == "converged" and "q6_deg" in out.columns
    tables = convergence_tables(d)
    poor = [t for t in tables if t.signature.startswith("poor")]
    assert abs(poor[0].rows[0, 4] - 6.8) < 0.05  # Table 5-1's 6.806 cm start
    nr, jac = poor
    assert nr.rows[-1, 4] < 1e-6 and jac.rows[-1, 4] < 1e-6
    assert len(nr.rows) < len(jac.rows)  # quadratic versus linear convergence


def test_user_tool_round_trip(robot3: Controller) -> None:
    # A gripper 12 cm out along the flange z, tilted 30° about its x, offset 2 cm in y.
    from pipeline.kinematics.transforms import transform_from_xyz_rpy

    F_u = transform_from_xyz_rpy([0.0, 2.0, 12.0], np.deg2rad([30.0, 0.0, 0.0]))
    user = robot3.with_tool(F_u)
    q, T_sig = _targets(robot3, 300, 9)
    # Independently: user tool = signature tool · Y⁻¹ · F_u (Y: flange -> signature tool).
    T_user = T_sig @ invert_transform(robot3.flange_to_tool) @ F_u
    b = parse_branch("right-up-noflip")
    on = np.all(puma560.branch_of(q) == [b.shoulder, b.elbow, b.wrist], axis=1)
    assert on.sum() > 20
    for method in ("nr", "jacobi"):
        r = user.solve(T_user[on], branch=b, method=method)
        assert r.converged.all() and r.position_error_cm.max() <= 1e-7
        # The solve stops within 1e-7 cm / 1e-10 rad of the pose; the joints then
        # lie within ~2e-9 rad of q (measured), 1e-7 rad leaves room near singularities.
        np.testing.assert_allclose(puma560.wrap_angle(r.q - q[on]), 0.0, atol=1e-7)
    # Without the user tool the probe, not the gripper, goes to those poses: other joints.
    r = robot3.solve(T_user[on], branch=b)
    assert np.abs(puma560.wrap_angle(r.q - q[on])).max(axis=1).min() > 1e-2
    # The signature's own tool as the "user" tool gives the signature's answer.
    same = robot3.with_tool(robot3.flange_to_tool).solve(T_sig[on], branch=b)
    np.testing.assert_allclose(same.q, robot3.solve(T_sig[on], branch=b).q, atol=1e-9)
    with pytest.raises(ArmsigError, match="bad user tool"):
        robot3.with_tool(np.diag([2.0, 1.0, 1.0, 1.0]))


def test_cli_ik_user_tool(robot3: Controller, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from pipeline.cli import app
    from pipeline.kinematics.transforms import transform_from_xyz_rpy, xyz_rpy_from_transform

    d = tmp_path / "s"
    d.mkdir()
    shutil.copy(ROOT / "sessions/robot3/recording.mcap", d)
    identify(d, report=False)
    q = np.deg2rad([10.0, -30.0, 160.0, 20.0, 40.0, -15.0])
    tool = (1.0, -2.0, 15.0, 0.0, 45.0, 0.0)
    F_u = transform_from_xyz_rpy(tool[:3], np.deg2rad(tool[3:]))
    T_sig = invert_transform(robot3.sensor_from_base) @ forward_kinematics(
        robot3.signature.chain, q
    )
    xyz, rpy = xyz_rpy_from_transform(T_sig @ invert_transform(robot3.flange_to_tool) @ F_u)
    pose = [*map(str, xyz), *map(str, np.rad2deg(rpy))]
    branch = next(b.label for b in puma560.BRANCHES
                  if list(puma560.branch_of(q)) == [b.shoulder, b.elbow, b.wrist])  # fmt: skip
    args = ["ik", str(d), "--pose", *pose, "--branch", branch]
    r = CliRunner().invoke(app, [*args, "--tool", *map(str, tool)])
    assert r.exit_code == 0, r.output
    q_out = [float(v) for v in r.output.split("\n")[0].split()[2::2]]
    np.testing.assert_allclose(q_out, np.rad2deg(q), atol=1e-4)  # printed to 1e-4°


def test_q_near_picks_the_branch_of_each_target(robot3: Controller) -> None:
    q, T = _targets(robot3, 200, 12)
    flags = puma560.branch_of(q)
    assert len({tuple(f) for f in flags}) >= 4  # several branches in one batch
    near = q + 0.05  # 3° off; a few cross a branch boundary and ask for another branch
    wanted = puma560.branch_of(near)
    same = np.all(wanted == flags, axis=1)
    assert 0.8 < same.mean() < 1.0
    for method in ("nr", "jacobi"):
        r = robot3.solve(T, method=method, q_near=near)
        ok = r.converged & np.all(puma560.branch_of(r.q) == wanted, axis=1)
        # Misses: targets within 3° of a singularity, asked for the branch across it.
        assert ok.mean() >= 0.97 and ok[same].all()
        # Same branch and 2π class as q (joint limits wider than ±180°): q itself.
        np.testing.assert_allclose(r.q[same], q[same], atol=1e-7)
    # Without q_near every target gets the signature configuration's arm branch
    # (shoulder, elbow); its wrist flag unless only the flipped wrist is inside the limits.
    r = robot3.solve(T)
    home = puma560.branch_of(robot3.signature.chain.joint_offsets)
    got = puma560.branch_of(r.q)
    assert np.all(got[:, :2] == home[:2], axis=1).mean() >= 0.95
    flipped = r.converged & (got[:, 2] != home[2])
    assert flipped.any()  # robot3's wrist_roll limits (-110..170°) leave some only flipped
    assert not outside_mask(r.q[flipped], robot3._limits).any()
    with pytest.raises(ArmsigError, match="bad start configuration"):
        robot3.solve(T[:3], q_near=np.zeros(5))


def test_realtime_one_target_equals_batch_bit_for_bit(robot3: Controller, monkeypatch) -> None:
    """The compiled start + solve (issue 18): the real-time call, one Controller.solve
    and a threaded batch give the same bits, near the wrist singularity too."""
    from pipeline.kinematics import ik_compiled

    b = parse_branch("right-up-noflip")
    q, T = _targets(robot3, 400, 8)
    on = np.all(puma560.branch_of(q) == [1, 1, 1], axis=1)
    q, T = q[on], T[on]
    q_sing = q[:20].copy()
    q_sing[:, 4] = np.random.default_rng(3).normal(0.0, 1e-3, 20)  # θ5 ≈ 0
    T = np.concatenate([T, invert_transform(robot3.sensor_from_base)
                        @ forward_kinematics(robot3.signature.chain, q_sing)])  # fmt: skip
    monkeypatch.setattr(ik_compiled, "THREADED_MIN_TARGETS", 2)  # the batch on threads
    batch = robot3.solve(T, branch=b)
    assert batch.converged[:-20].all()  # (a few of the θ5 ≈ 0 rows are off the branch)
    solver = robot3.realtime(b)
    assert robot3.realtime(b) is solver  # made once per branch
    for k in range(len(T)):
        ok = solver.solve_one(T[k])
        one = robot3.solve(T[k], branch=b)
        assert ok == one.converged[0] == batch.converged[k]
        np.testing.assert_array_equal(solver.q, batch.q[k])
        np.testing.assert_array_equal(one.q[0], batch.q[k])
        assert one.iterations[0] == batch.iterations[k] == solver.info[1]


def test_realtime_start_is_the_design_inverse(robot3: Controller) -> None:
    b = parse_branch("left-down-flip")
    _, T = _targets(robot3, 50, 9)
    solver = robot3.realtime(b)
    q_near = np.linspace(-7.0, 7.0, 6)  # a 2π class away from 0 for some joints
    ref = robot3.initial_estimate(robot3.sensor_from_base @ T, b, q_near)
    for k in range(len(T)):
        solver.solve_one(T[k], q_near)
        # The same closed form in another order of operations: round-off apart.
        np.testing.assert_allclose(solver.q0, ref[k], rtol=0, atol=1e-9)


def test_realtime_allocates_nothing(robot3: Controller) -> None:
    import tracemalloc

    solver = robot3.realtime(parse_branch("right-up-noflip"))
    q, T = _targets(robot3, 1000, 10)
    T = np.ascontiguousarray(T[np.all(puma560.branch_of(q) == [1, 1, 1], axis=1)])
    near = np.array(robot3.signature.chain.joint_offsets, float)
    for k in range(5):
        solver.solve_one(T[k], near)
    converged = np.zeros(100, bool)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        for k in range(100):
            converged[k] = solver.solve_one(T[k], near)
        after, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert converged.all()
    # Nothing kept, and at no time more than a few small Python objects of the
    # call itself (measured: 0 kept, peak ~4 KB over the 100 calls).
    assert after == before and peak - before < 16_000


def test_realtime_unreachable_target_is_reported(robot3: Controller) -> None:
    """A pose far out of reach: the kernel defers, the numpy iteration reports it."""
    b = parse_branch("right-up-noflip")
    T = np.eye(4)
    T[:3, 3] = (500.0, 0.0, 0.0)  # cm: beyond the arm's ~90 cm reach
    solver = robot3.realtime(b)
    assert not solver.solve_one(T)
    one = robot3.solve(T, branch=b)
    assert not one.converged[0]
    np.testing.assert_array_equal(solver.q, one.q[0])


def test_near_wrist_singularity_every_target_is_solved(robot3: Controller) -> None:
    """Regression (issue 18): within ~1° of the wrist singularity the design start
    fixes θ4 + θ6 but not θ4; the signature's θ4 can lie 1-2 rad away behind a
    local minimum, which Newton and Levenberg-Marquardt steps do not cross
    (before: 44 of these 580 targets unsolved, 5 more solved on another branch
    without a flag). The restarts with θ4 and θ6 turned against each other
    solve them on the branch, else flagged on another."""
    b = parse_branch("right-up-noflip")
    rng = np.random.default_rng(12)
    lim = np.deg2rad(robot3.robot.limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (3000, 6))
    q[:, 4] = np.abs(rng.normal(0.0, np.deg2rad(0.5), len(q)))  # θ5 within ~1°
    q = q[np.all(puma560.branch_of(q) == [1, 1, 1], axis=1)]
    T = invert_transform(robot3.sensor_from_base) @ forward_kinematics(robot3.signature.chain, q)
    r = robot3.solve(T, branch=b)
    # Issue 30: next to the singularity a signature has more solutions on one branch
    # than the solution and its wrist flip; the restarts (puma560.WRIST_TURNS) find the
    # one inside the limits for all but 3 of these 580 (their in-limit solution's basin
    # is narrower than the turns' spacing): flagged out_of_limits, none silently.
    limited = r.status == STATUS_OUT_OF_LIMITS
    assert (r.converged | limited).all() and limited.sum() <= 3
    assert not outside_mask(r.q[r.converged], robot3._limits).any()
    assert r.position_error_cm.max() <= 1e-7 and r.orientation_error_rad.max() <= 1e-10
    on = np.all(puma560.branch_of(r.q) == [1, 1, 1], axis=1)
    on_arm = np.all(puma560.branch_of(r.q)[:, :2] == [1, 1], axis=1)
    assert r.branch_changed is not None
    assert r.branch_changed[~on_arm].all() and not r.branch_changed[on].any()
    # Issue 45: every converged answer off the requested branch is flagged, a wrist flag
    # changed by the restarts into the limits too (before: 1 of these unflagged).
    assert r.branch_changed[r.converged & ~on].all()
    assert on.mean() >= 0.99
    solver = robot3.realtime(b)
    for k in np.flatnonzero(r.converged & ~on):
        assert solver.solve_one(T[k]) and solver.branch_changed


def test_jacobi_compiled_agrees_with_numpy(robot3: Controller, monkeypatch) -> None:
    """The compiled Jacobi iteration (issue 18 item 4) against the numpy one from the
    same start: same convergence, solutions within the tolerances' reach; a
    threaded batch equals single solves bit for bit."""
    from pipeline.kinematics import ik, ik_compiled
    from pipeline.robots.puma560 import wrap_angle

    b = parse_branch("right-up-noflip")
    q, T = _targets(robot3, 3000, 13)
    T = T[np.all(puma560.branch_of(q) == [1, 1, 1], axis=1)]
    monkeypatch.setattr(ik_compiled, "THREADED_MIN_TARGETS", 2)
    fast = robot3.solve(T, branch=b, method="jacobi")
    T_s = robot3.sensor_from_base @ T
    design = robot3._design_model(robot3.sensor_from_base)
    inv = robot3._design_inverse(b, jacobi=True)
    q0 = robot3.initial_estimate(T_s, b)
    slow = ik.jacobi_iterative(robot3.signature.chain, design, inv, T_s, q0, robot3.resolution)
    np.testing.assert_array_equal(fast.converged, slow.converged)
    ok = fast.converged
    assert ok.mean() >= 0.99
    # Joint values agree where the wrist is conditioned: near θ5 = 0 the pose fixes only
    # θ4 + θ6, and two accurate solutions may split it differently (4.6e-7 rad seen on a
    # refined signature); the pose errors below hold for every target.
    wrist = ok & (np.abs(np.sin(slow.q[:, 4])) > 0.05)
    np.testing.assert_allclose(wrap_angle(fast.q[wrist] - slow.q[wrist]), 0.0, rtol=0, atol=1e-7)
    assert fast.position_error_cm[ok].max() <= 1e-7
    assert fast.orientation_error_rad[ok].max() <= 1e-10
    for k in range(0, len(T), 17):
        one = robot3.solve(T[k], branch=b, method="jacobi")
        np.testing.assert_array_equal(one.q[0], fast.q[k])
        assert one.iterations[0] == fast.iterations[k] and one.status[0] == fast.status[k]


def test_realtime_trajectory_passes_its_own_solution_back(robot3: Controller) -> None:
    """``solve_one(T, solver.q)`` (the README's loop) reads q_near before it writes q."""
    b = parse_branch("right-up-noflip")
    lim = np.deg2rad(robot3.robot.limits)
    q_path = np.linspace(lim[:, 0] * 0.3, lim[:, 1] * 0.3, 40)
    q_path[:, 4] = np.abs(q_path[:, 4]) + 0.2  # the wrist stays on its branch
    T = invert_transform(robot3.sensor_from_base) @ forward_kinematics(
        robot3.signature.chain, q_path
    )
    solver = robot3.realtime(b)
    solver.q[:] = robot3.signature.chain.joint_offsets
    prev = solver.q.copy()
    for k in range(len(T)):
        assert solver.solve_one(T[k], solver.q)
        ref = robot3.solve(T[k], branch=b, q_near=prev)
        np.testing.assert_array_equal(solver.q, ref.q[0])
        prev = solver.q.copy()


def test_compiled_kernels_allocate_nothing_per_target(robot3: Controller) -> None:
    """Regression (issue 18, batched throughput): the batched Newton-Raphson and
    Jacobi kernels take their scratch once per call, not per target (before: ~15
    small arrays per Newton target, ~10 per Jacobi iteration). numba's own
    allocation counter: a 200-target batch allocates hardly more than a 10-target one."""
    from numba.core.runtime import _nrt_python, rtsys

    from pipeline.control.limits import shift_into

    b = parse_branch("right-up-noflip")
    q, T = _targets(robot3, 3000, 11)
    T = np.ascontiguousarray(T[np.all(puma560.branch_of(q) == [1, 1, 1], axis=1)][:200])
    assert len(T) == 200
    solver = robot3.realtime(b)
    near = np.broadcast_to(robot3.signature.chain.joint_offsets, (200, 6))
    _nrt_python.memsys_enable_stats()

    def allocations(solve, m: int) -> int:
        before = rtsys.get_allocation_stats().alloc
        res = solve(T[:m], near[:m])
        assert res.converged.all()
        return int(rtsys.get_allocation_stats().alloc - before)

    for solve in (solver.solve, solver.solve_jacobi):
        allocations(solve, 10)  # compiled and warm
        # Only the few targets that take Levenberg-Marquardt steps or Anderson
        # acceleration allocate (their matrices and pinv's): measured 11 more (Newton)
        # and 77 more (Jacobi) for the 190 more targets; before, 2,693 more (Newton).
        assert allocations(solve, 200) - allocations(solve, 10) <= 100
    # The batch comes back shifted into the joint limits (by the kernel, not the controller).
    res = robot3.solve(T, branch=b)
    shifted = res.q.copy()
    shift_into(shifted, *robot3._limits)
    np.testing.assert_array_equal(shifted, res.q)


@pytest.mark.parametrize("near", [False, True])
def test_one_target_equals_a_threaded_batch(robot3: Controller, monkeypatch, near: bool) -> None:
    """Controller.solve of one target (the real-time kernel with its own buffers) against
    the same targets in a threaded batch: every field bit for bit, including the targets
    solved off the branch (flagged); a result keeps its values after later solves, and
    the real-time solver's buffers are left alone (issue 18: one target)."""
    from pipeline.kinematics import ik_compiled

    b = parse_branch("right-up-noflip")
    rng = np.random.default_rng(21)
    lim = np.deg2rad(robot3.robot.limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (400, 6))
    q[::4, 4] = np.abs(rng.normal(0.0, np.deg2rad(0.5), len(q[::4])))  # some near the wrist
    q = q[np.all(puma560.branch_of(q) == [1, 1, 1], axis=1)][:60]
    T = invert_transform(robot3.sensor_from_base) @ forward_kinematics(robot3.signature.chain, q)
    q_near = q + 0.01 if near else None
    monkeypatch.setattr(ik_compiled, "THREADED_MIN_TARGETS", 2)
    batch = robot3.solve(T, branch=b, q_near=q_near)
    solver = robot3.realtime(b)
    solver.q[:] = 7.0
    ones = [
        robot3.solve(T[k], branch=b, q_near=None if q_near is None else q_near[k])
        for k in range(len(T))
    ]
    np.testing.assert_array_equal(solver.q, 7.0)
    assert all(vars(one).keys() == vars(batch).keys() for one in ones)  # every field set
    fields = ("q", "converged", "iterations", "position_error_cm", "orientation_error_rad",
              "status", "branch_changed")  # fmt: skip
    for name in fields:
        got = np.concatenate([getattr(one, name) for one in ones])
        np.testing.assert_array_equal(got, getattr(batch, name), err_msg=name)
        assert got.dtype == getattr(batch, name).dtype, name


def test_one_target_passes_few_arrays(robot3: Controller) -> None:
    """Regression (issue 18, one-target latency): Controller.solve of one target makes
    one compiled call of six arrays (the model and scratch packed once per solver);
    numba wraps each array argument in one record of its runtime, so its allocation
    counter counts the arrays passed: 6 per target (before: 32, ~5.8 µs of dispatch)."""
    from numba.core.runtime import _nrt_python, rtsys

    b = parse_branch("right-up-noflip")
    q, T = _targets(robot3, 400, 11)
    T = T[np.all(puma560.branch_of(q) == [1, 1, 1], axis=1)][:50]
    robot3.solve(T[0], branch=b)  # compiled and warm
    _nrt_python.memsys_enable_stats()
    before = rtsys.get_allocation_stats().alloc
    for k in range(len(T)):
        assert robot3.solve(T[k], branch=b).converged[0]
    # 6 per call, and a few targets' Levenberg-Marquardt scratch (11 arrays each)
    assert rtsys.get_allocation_stats().alloc - before <= 6 * len(T) + 25


def test_sensor_targets_of_the_finish_are_the_kernels(robot3: Controller) -> None:
    """The batched kernel keeps no target in the sensor frame (issue 45); the rows the
    numpy finish needs are formed by ``in_sensor_frame``: the kernel's products, bit for
    bit (the real-time solver keeps the last one)."""
    from pipeline.control.puma560_solver import in_sensor_frame

    q, T = _targets(robot3, 20, 13)
    solver = robot3.realtime(parse_branch("right-up-noflip"))
    formed = in_sensor_frame(solver._X, T)
    for k in range(len(T)):
        solver.solve_one(T[k])
        np.testing.assert_array_equal(solver._target, formed[k])
