"""Index definitions of the grid-touching tasks on hand-made point sets with known answers."""

import numpy as np
import pytest

from pipeline.evaluation.geometry import (
    normal_deviation,
    rotation_from_vector,
    rotation_vector,
    signed_extreme,
    workspace_from_points,
)
from pipeline.evaluation.indices import (
    GRID2D_INDICES,
    GRID3D_INDICES,
    grid2d_indices,
    grid3d_indices,
    improvement,
    line_length_errors,
)
from pipeline.evaluation.tasks import GRID2D_SHAPE, GRID3D_SHAPE, puma_tasks
from tests.conftest import random_rigid

# 1e-9 cm / deg: the index arithmetic is exact to round-off on these sizes (~1e-13).
TOL = 1e-9


def _grid2d() -> np.ndarray:
    return puma_tasks()[1].points_cm[:, :2].reshape(*GRID2D_SHAPE, 2)


def _grid3d() -> np.ndarray:
    return puma_tasks()[2].points_cm.reshape(*GRID3D_SHAPE, 3)


def test_workspace_frame_recovers_the_fixture(rng) -> None:
    F = random_rigid(rng, 20)
    local = np.array([[0.0, 0.0, 0.0], [60.0, 0.0, 0.0], [7.0, 25.0, 0.0]])
    p = np.einsum("mij,kj->mki", F[:, :3, :3], local) + F[:, None, :3, 3]
    W = workspace_from_points(p[:, 0], p[:, 1], p[:, 2])
    np.testing.assert_allclose(W, F, atol=1e-12)
    # batch == loop of singles
    for k in range(3):
        np.testing.assert_allclose(workspace_from_points(*p[k]), W[k], atol=0)


def test_workspace_frame_rejects_collinear_points() -> None:
    from pipeline.errors import KinematicsError

    with pytest.raises(KinematicsError, match="plane"):
        workspace_from_points([0, 0, 0], [1, 0, 0], [2, 0, 0])


def test_rotation_vector_round_trip(rng) -> None:
    w = rng.normal(size=(50, 3))
    w *= (rng.uniform(0, 3.0, 50) / np.linalg.norm(w, axis=1))[:, None]  # angles below π
    R0 = rotation_from_vector(rng.normal(size=(50, 3)))
    R = rotation_from_vector(w) @ R0
    np.testing.assert_allclose(rotation_vector(R0, R), w, atol=1e-10)
    np.testing.assert_allclose(rotation_from_vector(np.zeros(3)), np.eye(3), atol=0)


def test_bent_line_normal_deviation() -> None:
    a, b = np.array([0.0, 0.0, 0.0]), np.array([60.0, 0.0, 0.0])
    pts = np.array([[10.0, 0.0, 0.0], [30.0, 0.3, 0.4], [50.0, 0.0, -0.1]])
    np.testing.assert_allclose(normal_deviation(pts, a, b), [0.0, 0.5, 0.1], atol=TOL)


def test_signed_extreme_keeps_sign() -> None:
    assert signed_extreme([0.1, -0.3, 0.2]) == -0.3
    np.testing.assert_array_equal(signed_extreme([[1.0, -2.0], [3.0, 0.5]]), [-2.0, 3.0])


def test_line_length_errors_and_improvement() -> None:
    np.testing.assert_allclose(line_length_errors([59.47, 50.35], [60.0, 50.0]), [-0.53, 0.35])
    np.testing.assert_allclose(improvement([-0.53, 0.1, 0.0, 0.2], [0.05, -0.1, 0.0, 0.0]),
                               [10.6, 1.0, 1.0, np.inf])  # fmt: skip


def test_grid2d_perfect_scaled_skewed_bent() -> None:
    g = _grid2d()
    np.testing.assert_allclose(grid2d_indices(g, g), np.zeros(5), atol=TOL)
    s = 0.01  # scaled by 1 %: X lines 60 cm, Y lines 15 cm, diagonals √(60² + 15²)
    diag = np.hypot(60.0, 15.0)
    np.testing.assert_allclose(
        grid2d_indices(g * (1 + s), g), [60 * s, 15 * s, 0.0, diag * s, diag * s], atol=TOL
    )
    k = 0.02  # skewed: x += k·y; X lines keep their length, Y lines lean
    sk = g.copy()
    sk[..., 0] += k * g[..., 1]
    want = [0.0, 15 * np.hypot(1, k) - 15, 0.0, np.hypot(60 + 15 * k, 15) - diag,
            np.hypot(-60 + 15 * k, 15) - diag]  # fmt: skip
    np.testing.assert_allclose(grid2d_indices(sk, g), want, atol=TOL)
    bent = g.copy()
    bent[6, 1, 1] += 0.25  # middle mark of line X2 off its line by 0.25 cm
    out = grid2d_indices(bent, g)
    assert out[2] == pytest.approx(0.25, abs=TOL)
    assert [n for n, _, _ in GRID2D_INDICES][2] == "max_normal_deviation_cm"


def test_grid2d_batch_equals_loop(rng) -> None:
    g = _grid2d()
    marks = g + rng.normal(0, 0.05, (4, *g.shape))
    out = grid2d_indices(marks, g)
    for k in range(4):
        np.testing.assert_allclose(out[k], grid2d_indices(marks[k], g), atol=0)


def test_grid3d_scaled_grid() -> None:
    g = _grid3d()
    w0 = np.zeros_like(g)
    s = 0.005
    out = grid3d_indices(g * (1 + s), w0, g, w0)
    want = np.zeros(12)
    want[3:6] = [60 * s, 25 * s, 25 * s]
    np.testing.assert_allclose(out, want, atol=TOL)


def test_grid3d_skewed_grid_and_bent_line() -> None:
    g = _grid3d()
    w0 = np.zeros_like(g)
    k = 0.01
    sk = g.copy()
    sk[..., 0] += k * g[..., 1]  # Y lines lean toward +X: X-Y angle = 90° - atan(k)
    out = grid3d_indices(sk, w0, g, w0)
    assert out[6] == pytest.approx(-np.degrees(np.arctan(k)), abs=TOL)
    np.testing.assert_allclose(out[[7, 8]], 0.0, atol=TOL)
    assert out[4] == pytest.approx(25 * np.hypot(1, k) - 25, abs=TOL)
    bent = g.copy()
    bent[3, 1, 2, 2] += 0.04  # vertex (4, 2, 3) lifted 0.04 cm: middle of an X and a Y line
    out = grid3d_indices(bent, w0, g, w0)
    np.testing.assert_allclose(out[:3], [0.04, 0.04, 0.0], atol=TOL)
    assert out[5] == pytest.approx(0.04, abs=TOL)  # the end of its Z line: that line is longer


def test_grid3d_relative_orientation_at_vertex4() -> None:
    g = _grid3d()
    w = np.zeros_like(g)
    w[...] = [0.3, -0.2, 0.1]  # a constant deviation: no relative error
    R_dev = rotation_from_vector(np.deg2rad(w[0, 0, 0]))
    R4 = rotation_from_vector(np.deg2rad([0.0, 0.0, 0.05])) @ R_dev  # 0.05° more about Z
    w[-1, -1, 0] = np.degrees(rotation_vector(np.eye(3), R4))
    out = grid3d_indices(g, w, g, np.zeros_like(g))
    np.testing.assert_allclose(out[9:], [0.0, 0.0, 0.05], atol=TOL)
    assert [n for n, _, _ in GRID3D_INDICES][11] == "relative_orientation_z_vertex4_deg"


def test_grid3d_batch_equals_loop(rng) -> None:
    g = _grid3d()
    p = g + rng.normal(0, 0.05, (3, *g.shape))
    w = rng.normal(0, 0.1, (3, *g.shape))
    out = grid3d_indices(p, w, g, np.zeros_like(g))
    for k in range(3):
        np.testing.assert_allclose(out[k], grid3d_indices(p[k], w[k], g, np.zeros_like(g)),
                                   atol=1e-12)  # fmt: skip


def test_tasks_for_other_robots_map_the_layout() -> None:
    from pipeline.evaluation.tasks import down_workspace, tasks_for
    from pipeline.kinematics.transforms import trans
    from pipeline.robots import get_robot

    tool = trans(0.0, 0.0, 15.0)
    puma, stanford = get_robot("puma560"), get_robot("stanford")
    assert all(
        np.array_equal(a.points_cm, b.points_cm)
        for a, b in zip(tasks_for(puma, tool), puma_tasks(), strict=True)
    )
    w, wp = down_workspace(stanford, tool), down_workspace(puma, tool)
    s_xy = w.radius_cm / wp.radius_cm
    s_z = min(s_xy, (w.z_high_cm - w.z_low_cm) / (wp.z_high_cm - wp.z_low_cm))
    for a, b in zip(tasks_for(stanford, tool), puma_tasks(tilt=False), strict=True):
        np.testing.assert_allclose(a.points_cm, b.points_cm * [s_xy, s_xy, s_z])
        np.testing.assert_allclose(a.tool_rotation, b.tool_rotation)
        np.testing.assert_allclose(a.fixture_in_base[:2, 3], s_xy * b.fixture_in_base[:2, 3])
