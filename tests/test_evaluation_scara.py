"""``pipeline evaluate`` on an arm with fewer than six joints: the SCARA-like RRPR arm.

The arm controls x, y, z and the rotation about Z only (task axes); the tasks are
fitted inside its reach with the probe straight down, orientation indices use the
controlled component, and the ones without one are left out (docs/evaluation.md).
Simulations are small (12 points per sweep, one cycle) to keep the file fast.
"""

import numpy as np
import pytest

from pipeline.control.controller import solve_poses, task_axes_for
from pipeline.control.session import session_controller
from pipeline.evaluate import evaluate
from pipeline.evaluation.score import dropped_indices, restrict_orientation
from pipeline.evaluation.tasks import (
    FIT_MARGIN_CM,
    DownWorkspace,
    fit_task,
    puma_tasks,
    tasks_for,
)
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.transforms import invert_transform, rot_z, trans
from pipeline.rig.evaluation import EvaluationRigOptions
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.rig.true_robot import ErrorSigmas
from pipeline.robots import get_robot

SCARA = get_robot("scara")
EXACT_RIG = EvaluationRigOptions(perfect_servo=True, exact_instruments=True)
# Issue 6's exactness bound (cm or deg); the solvers stop at 1e-7 cm / 1e-10 rad.
EXACT_TOL = 1e-5
SMALL = {"robot": "scara", "points": 12, "repeats": 1}


def _all(summary: dict, who: str) -> np.ndarray:
    return np.array([abs(i[who]) for t in summary["tasks"].values() for i in t["indices"]])


@pytest.fixture(scope="module")
def noisy(tmp_path_factory):
    sdir = tmp_path_factory.mktemp("scara") / "s"
    simulate_session(sdir, SimulationOptions(seed=3, **SMALL))
    return sdir, evaluate(sdir)


def test_scara_is_evaluated_on_every_task(noisy) -> None:
    sdir, r = noisy
    s = r.summary
    assert s["controlled"] == ["x", "y", "z", "rz"] and not s["skipped"]
    sizes = {t: len(v["indices"]) for t, v in s["tasks"].items()}
    assert sizes == {"lines1d": 6, "grid2d": 5, "grid3d": 10, "grid12": 34}
    assert s["tasks"]["grid3d"]["not_applicable"] == [
        "relative_orientation_x_vertex4_deg",
        "relative_orientation_y_vertex4_deg",
    ]
    names = [i["name"] for i in s["tasks"]["grid12"]["indices"]]
    assert "vertex1_orientation_error_z_deg" in names
    assert "vertex4_relative_orientation_error_z_deg" in names
    assert all(np.isfinite(_all(s, "design"))) and all(np.isfinite(_all(s, "signature")))
    text = (sdir / "report" / "evaluation.md").read_text()
    assert "controls only x, y, z, rz" in text and "relative_orientation_x_vertex4_deg" in text


def test_scara_second_run_does_no_work(noisy) -> None:
    sdir, _ = noisy
    r = evaluate(sdir)
    assert {x.action for x in r.runs} == {"cached"} and r.recorded == []


def test_scara_noiseless_signature_is_exact(tmp_path) -> None:
    sdir = tmp_path / "s"
    simulate_session(sdir, SimulationOptions(seed=4, noiseless=True, **SMALL))
    s = evaluate(sdir, rig=EXACT_RIG, report=False).summary
    assert len(s["tasks"]) == 4
    assert _all(s, "signature").max() <= EXACT_TOL
    assert _all(s, "design").max() > 0.05  # the design model does err on this arm


def test_scara_design_is_exact_on_a_perfect_arm(tmp_path) -> None:
    sdir = tmp_path / "s"
    sigmas = ErrorSigmas(0.0, 0.0, 0.0)
    simulate_session(sdir, SimulationOptions(seed=4, noiseless=True, sigmas=sigmas, **SMALL))
    s = evaluate(sdir, rig=EXACT_RIG, report=False).summary
    assert len(s["tasks"]) == 4
    assert _all(s, "design").max() <= EXACT_TOL


def test_controller_solves_position_and_yaw(noisy, rng) -> None:
    sdir, _ = noisy
    c = session_controller(sdir)
    sig = c.signature.chain
    in_base = SerialChain(sig.links, sig.prismatic,
                          invert_transform(c.sensor_from_base) @ sig.base, sig.tool,
                          sig.joint_offsets)  # fmt: skip
    q = c.signature.chain.joint_offsets + rng.normal(0.0, 0.2, (50, 4)) * [1, 1, 10, 1]
    # Inside the limits with a margin: the probe-down rotation below moves the targets a
    # little off F(q), and a solution past a limit is out_of_limits (issue 30).
    margin = np.where(sig.prismatic, 0.5, 0.05)
    q = np.clip(q, c._limits[0] + margin, c._limits[1] - margin)
    T = forward_kinematics(in_base, q)
    T[:, :3, :3] = (rot_z(0.3) @ np.diag([1.0, -1.0, -1.0, 1.0]))[:3, :3]  # probe down
    axes = task_axes_for(SCARA)
    res = c.solve(T, task_axes=axes)
    assert res.converged.all() and res.task_axes == axes
    reached = forward_kinematics(in_base, res.q)
    assert np.abs(reached[:, :3, 3] - T[:, :3, 3]).max() <= 1e-6
    # `pipeline ik` (solve_poses) uses the arm's task axes by itself.
    xyz = T[:5, :3, 3]
    rpy = np.tile([180.0, 0.0, np.degrees(-0.3)], (5, 1))
    _, out = solve_poses(c, xyz, rpy)
    assert out.converged.all() and out.task_axes == axes


def test_tasks_fit_inside_the_scara_reach() -> None:
    tool = trans(0.0, 0.0, 15.0)
    from pipeline.evaluation.tasks import down_workspace

    w = down_workspace(SCARA, tool)
    for task in tasks_for(SCARA, tool):
        pts = np.concatenate([task.teach_cm, task.points_cm])
        p = pts @ task.fixture_in_base[:3, :3].T + task.fixture_in_base[:3, 3]
        assert np.hypot(p[:, 0], p[:, 1]).max() <= w.radius_cm - FIT_MARGIN_CM + 1e-9
        assert w.z_low_cm - 1e-9 <= p[:, 2].min() and p[:, 2].max() <= w.z_high_cm + 1e-9


def test_fit_task_scales_and_shifts_into_the_band() -> None:
    task = puma_tasks(tilt=False)[3]  # grid12: 60 x 30 x 50 cm, radius up to 76 cm
    inside = DownWorkspace(200.0, -100.0, 200.0)
    assert fit_task(task, inside) is task
    w = DownWorkspace(60.0 + FIT_MARGIN_CM, 0.0, 20.0)
    fit = fit_task(task, w)
    p = (fit.fixture_in_base @ fit.targets())[:, :3, 3]
    p0 = (task.fixture_in_base @ task.targets())[:, :3, 3]
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]).max(), 60.0, atol=1e-9)
    np.testing.assert_allclose([p[:, 2].min(), p[:, 2].max()], [0.0, 20.0], atol=1e-9)
    k = 60.0 / np.hypot(p0[:, 0], p0[:, 1]).max()
    np.testing.assert_allclose(p[:, :2], k * p0[:, :2], atol=1e-9)  # about the base Z axis


def test_restricted_orientation_indices_hand_made() -> None:
    """grid12 with yaw errors 0.1°, 0.3° at vertices 1 and 4 and a common 0.2° tilt."""
    from pipeline.evaluation import grid12

    names = list(zip(grid12.INDEX_NAMES, grid12.INDEX_UNITS, grid12.INDEX_SIGNED, strict=True))
    values = np.zeros((2, 34))
    w = np.zeros((2, 12, 3))
    w[:, :, 0] = 0.2  # uncontrolled tilt about X, everywhere
    w[1, 0, 2], w[1, 3, 2] = 0.1, 0.3
    out_names, out = restrict_orientation("grid12", names, values, w, (0, 1, 2, 5))
    got = dict(zip([n for n, _, _ in out_names], out[1], strict=True))
    assert got["vertex1_orientation_error_z_deg"] == pytest.approx(0.1)
    assert got["vertex4_orientation_error_z_deg"] == pytest.approx(0.3)
    assert got["vertex5_orientation_error_z_deg"] == 0.0
    assert got["vertex4_relative_orientation_error_z_deg"] == pytest.approx(0.2)
    assert got["vertex5_relative_orientation_error_z_deg"] == pytest.approx(0.1)
    assert np.all(out[0] == 0.0) and len(out_names) == 34
    # Position only: every orientation index is left out.
    assert len(dropped_indices("grid12", (0, 1, 2))) == 7
    assert dropped_indices("grid12", tuple(range(6))) == []


def test_restricted_grid3d_relative_yaw() -> None:
    from pipeline.evaluation.indices import GRID3D_INDICES
    from pipeline.evaluation.tasks import GRID3D_SHAPE

    w = np.zeros((2, *GRID3D_SHAPE, 3))
    w[..., 1] = 0.5  # uncontrolled tilt about Y
    w[0, -1, -1, 0, 2], w[0, 0, 0, 0, 2] = 0.04, -0.01  # Vertex 4 and Vertex 1 yaws
    names, out = restrict_orientation("grid3d", list(GRID3D_INDICES), np.zeros((2, 12)),
                                      w.reshape(2, -1, 3), (0, 1, 2, 5))  # fmt: skip
    assert [n for n, _, _ in names][-1] == "relative_orientation_z_vertex4_deg"
    assert len(names) == 10
    assert out[0, -1] == pytest.approx(0.05) and out[1, -1] == 0.0
