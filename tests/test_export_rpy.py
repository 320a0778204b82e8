"""Roll-pitch-yaw of a rotation near gimbal lock (URDF origins are xyz + rpy)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.kinematics.transforms import transform_from_xyz_rpy, xyz_rpy_from_transform


def test_rpy_rebuilds_the_pose_near_gimbal_lock() -> None:
    # Before: rx came from atan2(R21, R22) alone, and the pose rebuilt from (rx, ry, rz) erred
    # by up to 1e-5 at cos(ry) = 1e-11 (9e-9 at 1e-8): a URDF origin 1e-5 rad off.
    rng = np.random.default_rng(1)
    worst = 0.0
    for eps in (1.0, 1e-3, 1e-6, 1e-8, 1e-10, 1e-11):
        for _ in range(100):
            ry = rng.choice([-1.0, 1.0]) * (np.pi / 2 - eps)
            zyx = [rng.uniform(-3, 3), ry, rng.uniform(-3, 3)]
            noise = Rotation.from_rotvec(rng.normal(size=3) * 1e-15)  # not built from angles
            T = np.eye(4)
            T[:3, :3] = (Rotation.from_euler("ZYX", zyx) * noise).as_matrix()
            xyz, rpy = xyz_rpy_from_transform(T)
            worst = max(worst, float(np.abs(transform_from_xyz_rpy(xyz, rpy) - T).max()))
    assert worst < 1e-14, worst  # round-off of a few products
