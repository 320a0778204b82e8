"""Forward kinematics of a robot chain (the design model, or a signature through
:meth:`pipeline.control.Controller.pose`) in boundary units (deg / cm in, cm / deg out)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.nongeometric import NonGeometric
from pipeline.kinematics.transforms import xyz_rpy_from_transform
from pipeline.robots.description import RobotDescription
from pipeline.units import joints_to_internal


@dataclass(frozen=True)
class ToolPose:
    """Tool pose of a chain at one joint configuration.

    ``matrix`` (4, 4) in cm; ``xyz_cm`` (3,); ``rpy_deg`` (3,) fixed-axis
    roll-pitch-yaw; ``outside_limits`` names joints beyond their limits.
    """

    matrix: np.ndarray
    xyz_cm: np.ndarray
    rpy_deg: np.ndarray
    outside_limits: tuple[str, ...]


def design_pose(robot: RobotDescription, q: list[float] | np.ndarray) -> ToolPose:
    """Forward kinematics of ``robot``'s design model (flange in the design base frame).

    Parameters
    ----------
    q : sequence of float, length n
        Joint readings in deg (revolute) / cm (prismatic).
    """
    return chain_pose(robot, robot.design_chain(), q)


@dataclass(frozen=True)
class ToolPoses:
    """Tool poses of a chain at ``m`` joint configurations: :class:`ToolPose`'s fields by
    row (``matrix`` (m, 4, 4), ``xyz_cm`` and ``rpy_deg`` (m, 3), ``outside_limits`` per row)."""

    matrix: np.ndarray
    xyz_cm: np.ndarray
    rpy_deg: np.ndarray
    outside_limits: list[tuple[str, ...]]


def chain_pose(
    robot: RobotDescription,
    chain: SerialChain,
    q: list[float] | np.ndarray,
    nongeometric: NonGeometric | None = None,
) -> ToolPose:
    """Forward kinematics of ``chain``, a chain of ``robot`` (same joints), at joint
    readings ``q`` (n,) in deg (revolute) / cm (prismatic), through the robot's coupling
    and, given them, the ``nongeometric`` terms (where the joints sit)."""
    qq = np.asarray(q, float)
    if qq.shape != (robot.n_joints,):
        raise KinematicsError(
            f"{robot.name}: wrong number of joint values",
            expected=f"{robot.n_joints} values ({', '.join(j.name for j in robot.joints)})",
            got=f"{qq.size}",
        )
    p = chain_poses(robot, chain, qq[None], nongeometric)
    return ToolPose(p.matrix[0], p.xyz_cm[0], p.rpy_deg[0], p.outside_limits[0])


def chain_poses(
    robot: RobotDescription,
    chain: SerialChain,
    q: np.ndarray,
    nongeometric: NonGeometric | None = None,
) -> ToolPoses:
    """:func:`chain_pose` of joint readings ``q`` (m, n), deg / cm, in one batch."""
    qq = np.asarray(q, float)
    joints = joints_to_internal(robot.joints_from_readings(qq), robot.prismatic)
    if nongeometric is not None:
        joints = nongeometric.effective(joints)
    T = forward_kinematics(chain, joints)
    xyz, rpy = xyz_rpy_from_transform(T)
    return ToolPoses(T, xyz, np.rad2deg(rpy), [outside_limits(robot, row) for row in qq])


def outside_limits(robot: RobotDescription, q: list[float] | np.ndarray) -> tuple[str, ...]:
    """The names of ``robot``'s joints whose readings ``q`` (n,) (deg / cm) lie outside
    their limits."""
    lim = robot.limits
    return tuple(
        j.name for j, v, (lo, hi) in zip(robot.joints, q, lim, strict=True) if not lo <= v <= hi
    )
