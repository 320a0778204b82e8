"""Appendix A primitives, inverse, pose helpers."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.kinematics import transforms as tf
from tests.conftest import random_rigid

angles = st.floats(-10.0, 10.0, allow_nan=False)


@given(angles)
def test_rotations_match_appendix_a(t: float) -> None:
    c, s = np.cos(t), np.sin(t)
    np.testing.assert_array_equal(
        tf.rot_x(t), [[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]]
    )
    np.testing.assert_array_equal(
        tf.rot_y(t), [[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]]
    )
    np.testing.assert_array_equal(
        tf.rot_z(t), [[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    )


def test_translations_match_appendix_a() -> None:
    np.testing.assert_array_equal(tf.trans_x(2.0)[:, 3], [2, 0, 0, 1])
    np.testing.assert_array_equal(tf.trans_y(3.0)[:, 3], [0, 3, 0, 1])
    np.testing.assert_array_equal(tf.trans_z(4.0)[:, 3], [0, 0, 4, 1])
    np.testing.assert_array_equal(tf.trans(1, 2, 3), tf.trans_x(1) @ tf.trans_y(2) @ tf.trans_z(3))


def test_batch_equals_loop(rng: np.random.Generator) -> None:
    t = rng.uniform(-4, 4, size=(5, 7))
    for f in (tf.rot_x, tf.rot_y, tf.rot_z, tf.trans_x, tf.trans_y, tf.trans_z):
        batch = f(t)
        assert batch.shape == (5, 7, 4, 4)
        loop = np.array([[f(v) for v in row] for row in t])
        np.testing.assert_array_equal(batch, loop)


def test_invert_transform(rng: np.random.Generator) -> None:
    T = random_rigid(rng, 1000)
    np.testing.assert_allclose(
        tf.invert_transform(T) @ T, np.tile(np.eye(4), (1000, 1, 1)), atol=1e-12
    )
    np.testing.assert_allclose(tf.invert_transform(T), np.linalg.inv(T), atol=1e-12)


def test_xyz_rpy_round_trip(rng: np.random.Generator) -> None:
    T = random_rigid(rng, 1000)
    xyz, rpy = tf.xyz_rpy_from_transform(T)
    np.testing.assert_allclose(tf.transform_from_xyz_rpy(xyz, rpy), T, atol=1e-12)
    # Gimbal lock: ry = ±90° still round-trips.
    for ry in (np.pi / 2, -np.pi / 2):
        T1 = tf.transform_from_xyz_rpy([1, 2, 3], [0.3, ry, -0.7])
        np.testing.assert_allclose(
            tf.transform_from_xyz_rpy(*tf.xyz_rpy_from_transform(T1)), T1, atol=1e-12
        )


def test_pose_error_and_differential_motion(rng: np.random.Generator) -> None:
    T = random_rigid(rng, 200)
    axis = rng.normal(size=(200, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0, 3.0, 200)
    # Rotation about a world axis by Rodrigues, applied on the left.
    K = np.zeros((200, 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K = K - np.swapaxes(K, 1, 2)
    R = np.eye(3) + np.sin(angle)[:, None, None] * K + (1 - np.cos(angle))[:, None, None] * K @ K
    T2 = T.copy()
    T2[:, :3, :3] = R @ T[:, :3, :3]
    T2[:, :3, 3] += 1.5
    dp, dth = tf.pose_error(T, T2)
    np.testing.assert_allclose(dp, np.sqrt(3 * 1.5**2), rtol=1e-12)
    np.testing.assert_allclose(dth, angle, atol=1e-10)
    delta = tf.differential_motion(T, T2)
    np.testing.assert_allclose(delta[:, :3], 1.5, atol=1e-12)
    np.testing.assert_allclose(delta[:, 3:], axis * angle[:, None], atol=1e-9)


@settings(max_examples=50)
@given(st.lists(angles, min_size=6, max_size=6))
def test_rotation_matrices_orthonormal(v: list[float]) -> None:
    T = tf.transform_from_xyz_rpy(v[:3], v[3:])
    R = T[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(R) - 1) < 1e-12
