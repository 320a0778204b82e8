"""URDF of a serial chain (SI units; format in docs/export.md).

A URDF joint moves its child as ``parent · origin · M(q)`` with ``M`` a rotation about, or a
translation along, the joint's axis (z here). The chain (5.1)-(5.3) is
``base · Π Rot(z, q_i − q0_i) · K̄_i · tool``; motions about one axis commute, so
``Rot(z, q − q0) = Rot(z, −q0) · Rot(z, q)`` and the encoder offset ``q0_i`` goes into the
joint's origin: joint ``i``'s origin is ``K̄_{i−1} · Rot(z, −q0_i)`` (``K̄_0 = base``), and the
URDF joint variable is the encoder reading itself (rad, m). The tool hangs on a fixed joint
with origin ``K̄_n · tool``; the flange frames of ROS-Industrial (REP-199) too: ``flange``
(x out of the flange) on the last link, ``tool0`` (z out of the flange) on ``flange``, with
``tool0`` at ``K̄_n · tool0_from_last`` (the physical flange, :func:`pipeline.export.flange_offset`).
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import (
    Array,
    invert_transform,
    rot_z,
    trans_z,
    transform_from_xyz_rpy,
    xyz_rpy_from_transform,
)
from pipeline.robots.description import JointSpec, RobotDescription

M_PER_CM = 0.01
BASE_LINK = "base_link"
TOOL_LINK = "tool"
TOOL_JOINT = "tool_joint"
FLANGE_LINK, FLANGE_JOINT = "flange", "flange_joint"
TOOL0_LINK, TOOL0_JOINT = "tool0", "tool0_joint"
#: ``tool0`` in ``flange`` (ROS-Industrial's ur_description, REP-199): rpy (π/2, 0, π/2), so
#: tool0's z is the flange's x (out of the flange) and tool0's x the flange's y.
TOOL0_IN_FLANGE = transform_from_xyz_rpy([0.0, 0.0, 0.0], [np.pi / 2, 0.0, np.pi / 2])
#: A camera's frames (ROS REP 103 and 105): ``camera_link`` (x forward, y left, z up) and
#: ``camera_optical_frame`` (z along the optical axis, x right, y down: OpenCV's, armsig's
#: camera frame) on it with rpy (−π/2, 0, −π/2).
CAMERA_LINK, CAMERA_JOINT = "camera_link", "camera_joint"
OPTICAL_LINK, OPTICAL_JOINT = "camera_optical_frame", "camera_optical_joint"
OPTICAL_IN_CAMERA_LINK = transform_from_xyz_rpy([0.0, 0.0, 0.0], [-np.pi / 2, 0.0, -np.pi / 2])
NO_RATES = (
    "velocity and effort limits: not in the robot description, written as 0 because urdfdom "
    "requires the attributes; set them (or velocity_limit and effort_limit in the "
    "description) before a planner uses this file"
)


def joint_origins(chain: SerialChain) -> Array:
    """Origins (cm) of the n moving joints and the fixed tool joint, shape (n + 1, 4, 4)."""
    q0 = np.asarray(chain.joint_offsets, float)
    offset = np.where(chain.prismatic[:, None, None], trans_z(-q0), rot_z(-q0))
    before = np.concatenate((chain.base[None], chain.links[:-1]))  # K̄_0 … K̄_{n−1}
    tool = chain.links[-1] @ chain.tool
    out: Array = np.concatenate((before @ offset, tool[None]))
    return out


def fixed_origins(chain: SerialChain, tool0_from_last: Array) -> Array:
    """Origins (cm) of the fixed joints of ``flange`` (on the last joint's link) and
    ``tool0`` (on ``flange``), shape (2, 4, 4); ``tool0_from_last``: tool0 in the last link
    frame ``F_n`` (4, 4)."""
    tool0 = chain.links[-1] @ tool0_from_last  # in the last URDF link, F_{n−1} Rot(z, ·)
    out: Array = np.stack((tool0 @ invert_transform(TOOL0_IN_FLANGE), TOOL0_IN_FLANGE))
    return out


def link_names(robot: RobotDescription) -> list[str]:
    """``base_link``, one link per joint named after it, ``flange``, ``tool0``, ``tool``;
    refused if two coincide (a joint named ``base``) or a joint is named like a fixed one."""
    links = [BASE_LINK, *(f"{j.name}_link" for j in robot.joints), FLANGE_LINK, TOOL0_LINK,
             TOOL_LINK]  # fmt: skip
    joints = [j.name for j in robot.joints]
    for names, kind in (
        (links, "link"),
        ([*joints, TOOL_JOINT, FLANGE_JOINT, TOOL0_JOINT], "joint"),
    ):
        dup = next((x for x in names if names.count(x) > 1), None)
        if dup is not None:
            raise ArmsigError(
                f"robot {robot.name}: the URDF would have two {kind}s named {dup!r}",
                fix="rename the joint in the robot description",
            )
    return links


def _num(v: float) -> str:
    return repr(float(v))  # shortest text that reads back to the same double


def origin_element(T: Array) -> str:
    """``<origin xyz rpy/>`` of ``T`` (cm), in metres and radians, each number the shortest
    text that reads back to the same double."""
    xyz, rpy = xyz_rpy_from_transform(T)
    xyz = xyz * M_PER_CM
    return (
        f'<origin xyz="{" ".join(_num(v) for v in xyz)}" rpy="{" ".join(_num(v) for v in rpy)}"/>'
    )


def _fixed(name: str, parent: str, child: str, origin: Array) -> list[str]:
    return [
        f'  <joint name={quoteattr(name)} type="fixed">',
        f"    <parent link={quoteattr(parent)}/>",
        f"    <child link={quoteattr(child)}/>",
        f"    {origin_element(origin)}",
        "  </joint>",
    ]


def _limit(j: JointSpec) -> str:
    """The ``<limit>`` element in SI units: position always, velocity and effort as the
    description gives them, else 0 (urdfdom requires both attributes)."""
    lo, hi = (
        (j.lower * M_PER_CM, j.upper * M_PER_CM) if j.prismatic else np.radians((j.lower, j.upper))
    )
    v = j.velocity_limit or 0.0
    v = v * M_PER_CM if j.prismatic else float(np.radians(v))
    e = j.effort_limit or 0.0
    return f'<limit lower="{_num(lo)}" upper="{_num(hi)}" effort="{_num(e)}" velocity="{_num(v)}"/>'


def camera_origins(optical_in_parent: Array) -> Array:
    """Origins (cm) of ``camera_link`` on its parent and of ``camera_optical_frame`` on
    ``camera_link`` (2, 4, 4), for the optical frame at ``optical_in_parent`` (4, 4)."""
    link = optical_in_parent @ invert_transform(OPTICAL_IN_CAMERA_LINK)
    return np.stack((link, OPTICAL_IN_CAMERA_LINK))


def urdf_text(
    chain: SerialChain,
    robot: RobotDescription,
    name: str,
    comment: str,
    tool0_from_last: Array,
    camera: tuple[str, Array] | None = None,
) -> str:
    """The URDF document of ``chain`` (cm, rad; single robot) with ``robot``'s names and
    limits, and the flange frames (:func:`fixed_origins`). ``comment`` (plain text) goes at
    the top: which model, which frame. ``camera``: a camera's parent link and its optical
    frame there (4, 4, cm): ``camera_link`` and ``camera_optical_frame``
    (:func:`camera_origins`)."""
    origins = joint_origins(chain)
    flange, tool0 = fixed_origins(chain, tool0_from_last)
    links = link_names(robot)
    lines = [
        '<?xml version="1.0"?>',
        f"<!-- {comment.replace('--', '-')} -->",
        f"<robot name={quoteattr(name)}>",
        *(f"  <link name={quoteattr(link)}/>" for link in links),
    ]
    n = robot.n_joints
    for i, j in enumerate(robot.joints):
        if j.velocity_limit is None or j.effort_limit is None:
            lines.append(f"  <!-- {j.name}: {NO_RATES} -->")
        lines += [
            f"  <joint name={quoteattr(j.name)} type={quoteattr(j.type)}>",
            f"    <parent link={quoteattr(links[i])}/>",
            f"    <child link={quoteattr(links[i + 1])}/>",
            f"    {origin_element(origins[i])}",
            '    <axis xyz="0 0 1"/>',
            f"    {_limit(j)}",
            "  </joint>",
        ]
    lines += [
        *_fixed(TOOL_JOINT, links[n], TOOL_LINK, origins[-1]),
        *_fixed(FLANGE_JOINT, links[n], FLANGE_LINK, flange),
        *_fixed(TOOL0_JOINT, FLANGE_LINK, TOOL0_LINK, tool0),
    ]
    if camera is not None:
        parent, optical = camera
        on_parent, on_link = camera_origins(optical)
        lines += [
            f"  <link name={quoteattr(CAMERA_LINK)}/>",
            f"  <link name={quoteattr(OPTICAL_LINK)}/>",
            *_fixed(CAMERA_JOINT, parent, CAMERA_LINK, on_parent),
            *_fixed(OPTICAL_JOINT, CAMERA_LINK, OPTICAL_LINK, on_link),
        ]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def chain_from_origins(origins_cm: Array, prismatic: Array) -> SerialChain:
    """The URDF's kinematics as a chain (cm; joint variable = reading): for checking it."""
    return SerialChain(origins_cm[1:], prismatic, origins_cm[0], np.eye(4))


def as_written(T: Array) -> Array:
    """Transforms (..., 4, 4), cm, as an ``<origin>`` states them: xyz in metres, rpy."""
    xyz, rpy = xyz_rpy_from_transform(T)
    out: Array = transform_from_xyz_rpy((xyz * M_PER_CM) / M_PER_CM, rpy)
    return out


def written_origins(chain: SerialChain) -> Array:
    """The joint origins as the URDF text states them (xyz, rpy rounded to its doubles), cm."""
    return as_written(joint_origins(chain))
