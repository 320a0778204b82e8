"""The 12-vertex grid of Table 7-1 and the 34 indices of Section 7.2.1 on hand-made poses."""

import numpy as np
import pytest

from pipeline.evaluation import grid12 as g
from pipeline.kinematics.transforms import rot_x, rot_z, trans
from tests.conftest import random_rigid

# Index positions by name, so the tests read like the thesis.
IX = {name: k for k, name in enumerate(g.INDEX_NAMES)}
# Hand-made poses are exact up to a few ulps of 100 cm coordinates.
TOL = 1e-10


def _with_positions(p: np.ndarray) -> np.ndarray:
    T = g.grid12_targets().copy()
    T[..., :3, 3] = p
    return T


def test_names_units_and_sign_counts() -> None:
    assert len(g.INDEX_NAMES) == len(set(g.INDEX_NAMES)) == 34
    assert sum(g.INDEX_SIGNED) == 19 and len(g.INDEX_SIGNED) == 34
    assert all(n.endswith("_" + u) for n, u in zip(g.INDEX_NAMES, g.INDEX_UNITS, strict=True))
    assert g.INDEX_UNITS.count("cm") == 16 + 4 + 4
    assert g.INDEX_NAMES[0] == "line1_length_error_cm"
    assert g.INDEX_NAMES[-1] == "perpendicularity_zx_error_deg"


def test_targets_match_table_7_1_and_text() -> None:
    T = g.grid12_targets()
    assert T.shape == (12, 4, 4)
    # Rot(y, 180°) Rot(z, 90°) written out: tool Z points down, tool X along base Y.
    np.testing.assert_allclose(
        g.GRID12_TOOL_ROTATION, [[0, 1, 0], [1, 0, 0], [0, 0, -1]], atol=1e-15
    )
    np.testing.assert_array_equal(T[:, :3, 3], g.GRID12_VERTICES_CM)
    v = g._line_vectors(g.GRID12_VERTICES_CM, g.LINE_VERTICES)
    # Lines 1, 4, 5, 8 along X (60 cm), 2, 3, 6, 7 along Y (30), 9-12 along Z (50).
    for lines, axis, length in (
        ((1, 4, 5, 8), 0, 60),
        ((2, 3, 6, 7), 1, 30),
        ((9, 10, 11, 12), 2, 50),
    ):
        for n in lines:
            expected = np.zeros(3)
            expected[axis] = length
            np.testing.assert_array_equal(v[n - 1], expected)
    # Vertices 9-12 are the midpoints of Lines 1, 4, 5, 8.
    for line, mid in g.NORMAL_DEVIATIONS:
        a, b = g.LINE_VERTICES[line - 1]
        p = g.GRID12_VERTICES_CM
        np.testing.assert_array_equal(p[mid - 1], (p[a - 1] + p[b - 1]) / 2)


def test_perfect_grid_gives_zero() -> None:
    T = g.grid12_targets()
    np.testing.assert_allclose(g.indices34(T, T), 0.0, atol=TOL)


def test_uniformly_scaled_grid() -> None:
    s = 1.01
    p = g.GRID12_VERTICES_CM * s
    idx = g.indices34(_with_positions(p), g.grid12_targets())
    desired = np.linalg.norm(g._line_vectors(g.GRID12_VERTICES_CM, g.LINE_VERTICES), axis=-1)
    np.testing.assert_allclose(idx[:16], (s - 1) * desired, atol=TOL)
    np.testing.assert_allclose(idx[:4], [0.6, 0.3, 0.3, 0.6], atol=TOL)
    for v in g.CORNER_VERTICES:
        expected = (s - 1) * np.linalg.norm(g.GRID12_VERTICES_CM[v - 1])
        assert idx[IX[f"vertex{v}_radial_error_cm"]] == pytest.approx(expected, abs=TOL)
    # Scaling keeps straightness, angles and orientations.
    np.testing.assert_allclose(idx[16:20], 0.0, atol=TOL)
    np.testing.assert_allclose(idx[24:], 0.0, atol=TOL)


def test_bent_line_gives_normal_deviation_only() -> None:
    p = g.GRID12_VERTICES_CM.copy()
    p[8] += [0.0, 0.3, -0.4]  # midpoint 9 of Line 1 off the line by 0.5 cm
    idx = g.indices34(_with_positions(p), g.grid12_targets())
    expected = np.zeros(34)
    expected[IX["line1_normal_deviation_cm"]] = 0.5
    np.testing.assert_allclose(idx, expected, atol=TOL)


def test_skewed_grid() -> None:
    k = 0.02  # x' = x + k (y - 40): shear in the X-Y plane about Vertex 1
    p = g.GRID12_VERTICES_CM.copy()
    p[:, 0] += k * (p[:, 1] - 40.0)
    idx = g.indices34(_with_positions(p), g.grid12_targets())
    y_error = 30.0 * (np.hypot(1.0, k) - 1.0)
    for n in (2, 3, 6, 7):
        assert idx[IX[f"line{n}_length_error_cm"]] == pytest.approx(y_error, abs=TOL)
    for n in (1, 4, 5, 8, 9, 10, 11, 12):
        assert abs(idx[IX[f"line{n}_length_error_cm"]]) < TOL
    d14 = np.hypot(60 + 30 * k, 30) - np.hypot(60, 30)
    d23 = np.hypot(60 - 30 * k, 30) - np.hypot(60, 30)
    assert idx[IX["diagonal1_4_length_error_cm"]] == pytest.approx(d14, abs=TOL)
    assert idx[IX["diagonal2_3_length_error_cm"]] == pytest.approx(d23, abs=TOL)
    assert idx[IX["perpendicularity_xy_error_deg"]] == pytest.approx(-np.degrees(np.arctan(k)))
    assert abs(idx[IX["perpendicularity_yz_error_deg"]]) < 1e-9
    assert abs(idx[IX["perpendicularity_zx_error_deg"]]) < 1e-9
    # Vertices 4 and 8 moved by 30 k along X; 1 and 5 stay.
    np.testing.assert_allclose(idx[20:24], [0, 30 * k, 0, 30 * k], atol=TOL)


def test_rigidly_moved_grid_keeps_relative_indices(rng: np.random.Generator) -> None:
    G = random_rigid(rng, 1, scale=5.0)[0]
    Td = g.grid12_targets()
    idx = g.indices34(G @ Td, Td)
    relative = [k for k, n in enumerate(g.INDEX_NAMES) if "radial" not in n and "vertex" not in n]
    relative += [IX[f"vertex{v}_relative_orientation_error_deg"] for v in (4, 5, 8)]
    np.testing.assert_allclose(idx[relative], 0.0, atol=1e-9)
    # Every absolute orientation error is the rotation angle of G.
    angle = np.degrees(np.arccos((np.trace(G[:3, :3]) - 1) / 2))
    np.testing.assert_allclose(idx[24:28], angle, rtol=1e-9)
    radial = np.linalg.norm((G @ Td)[:, :3, 3] - Td[:, :3, 3], axis=-1)[[0, 3, 4, 7]]
    np.testing.assert_allclose(idx[20:24], radial, rtol=1e-12)


def test_tool_twist_at_one_vertex() -> None:
    a = np.radians(0.7)
    Td = g.grid12_targets()
    Ta = Td.copy()
    Ta[4] = Td[4] @ rot_z(a) @ rot_x(a)  # vertex 5: two successive tool-frame rotations
    angle = np.degrees(np.arccos((np.trace((rot_z(a) @ rot_x(a))[:3, :3]) - 1) / 2))
    idx = g.indices34(Ta, Td)
    expected = np.zeros(34)
    expected[IX["vertex5_orientation_error_deg"]] = angle
    expected[IX["vertex5_relative_orientation_error_deg"]] = angle
    np.testing.assert_allclose(idx, expected, atol=1e-9)
    # Twisting the reference vertex 1 shows in all three relative errors.
    Ta = Td.copy()
    Ta[0] = Td[0] @ rot_x(a)
    idx = g.indices34(Ta, Td)
    np.testing.assert_allclose(idx[28:31], np.degrees(a), rtol=1e-9)


def test_batch_equals_loop(rng: np.random.Generator) -> None:
    Td = g.grid12_targets()
    # Small random motions: rotations of a few degrees, translations of a few mm.
    a = rng.normal(scale=0.05, size=(3, 3, 4, 12))
    d = rng.normal(scale=0.3, size=(3, 3, 4, 12))
    small = trans(*d) @ rot_z(a[0]) @ rot_x(a[1]) @ rot_z(a[2])
    Ta = small @ Td
    batch = g.indices34(Ta, Td)
    assert batch.shape == (3, 4, 34)
    loop = np.array([[g.indices34(Ta[i, j], Td) for j in range(4)] for i in range(3)])
    np.testing.assert_array_equal(batch, loop)
    nonneg = ~np.array(g.INDEX_SIGNED)
    assert (batch[..., nonneg] >= 0).all()


def test_rejects_wrong_shape() -> None:
    with pytest.raises(ValueError, match="12, 4, 4"):
        g.indices34(np.zeros((11, 4, 4)), g.grid12_targets())


def test_translation_only_error() -> None:
    # Moving vertex 8 by (1, 2, 2) cm: radial 3, Lines 8 and 6 and 12 and diagonal 5-8 change.
    Td = g.grid12_targets()
    Ta = Td.copy()
    Ta[7] = trans(1.0, 2.0, 2.0) @ Td[7]
    idx = g.indices34(Ta, Td)
    assert idx[IX["vertex8_radial_error_cm"]] == pytest.approx(3.0)
    assert idx[IX["line8_length_error_cm"]] == pytest.approx(np.sqrt(61**2 + 4 + 4) - 60)
    assert idx[IX["line12_length_error_cm"]] == pytest.approx(np.sqrt(1 + 4 + 52**2) - 50)
    assert idx[IX["line8_normal_deviation_cm"]] > 0
