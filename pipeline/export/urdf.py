"""URDF of a serial chain (SI units; format in docs/export.md).

A URDF joint moves its child as ``parent · origin · M(q)`` with ``M`` a rotation about, or a
translation along, the joint's axis (z here). The chain (5.1)-(5.3) is
``base · Π Rot(z, q_i − q0_i) · K̄_i · tool``; motions about one axis commute, so
``Rot(z, q − q0) = Rot(z, −q0) · Rot(z, q)`` and the encoder offset ``q0_i`` goes into the
joint's origin: joint ``i``'s origin is ``K̄_{i−1} · Rot(z, −q0_i)`` (``K̄_0 = base``), and the
URDF joint variable is the encoder reading itself (rad, m). The tool hangs on a fixed joint
with origin ``K̄_n · tool``.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import (
    Array,
    rot_z,
    trans_z,
    transform_from_xyz_rpy,
    xyz_rpy_from_transform,
)
from pipeline.robots.description import RobotDescription

M_PER_CM = 0.01
BASE_LINK = "base_link"
TOOL_LINK = "tool"
TOOL_JOINT = "tool_joint"


def joint_origins(chain: SerialChain) -> Array:
    """Origins (cm) of the n moving joints and the fixed tool joint, shape (n + 1, 4, 4)."""
    q0 = np.asarray(chain.joint_offsets, float)
    offset = np.where(chain.prismatic[:, None, None], trans_z(-q0), rot_z(-q0))
    before = np.concatenate((chain.base[None], chain.links[:-1]))  # K̄_0 … K̄_{n−1}
    tool = chain.links[-1] @ chain.tool
    out: Array = np.concatenate((before @ offset, tool[None]))
    return out


def link_names(robot: RobotDescription) -> list[str]:
    """``base_link``, one link per joint named after it, ``tool``; refused if two coincide
    (a joint named ``base``) or a joint is named like the tool's fixed joint."""
    links = [BASE_LINK, *(f"{j.name}_link" for j in robot.joints), TOOL_LINK]
    joints = [j.name for j in robot.joints]
    for names, kind in ((links, "link"), ([*joints, TOOL_JOINT], "joint")):
        dup = next((x for x in names if names.count(x) > 1), None)
        if dup is not None:
            raise ArmsigError(
                f"robot {robot.name}: the URDF would have two {kind}s named {dup!r}",
                fix="rename the joint in the robot description",
            )
    return links


def _num(v: float) -> str:
    return repr(float(v))  # shortest text that reads back to the same double


def _origin(T: Array) -> str:
    xyz, rpy = xyz_rpy_from_transform(T)
    xyz = xyz * M_PER_CM
    return (
        f'<origin xyz="{" ".join(_num(v) for v in xyz)}" rpy="{" ".join(_num(v) for v in rpy)}"/>'
    )


def urdf_text(chain: SerialChain, robot: RobotDescription, name: str, comment: str) -> str:
    """The URDF document of ``chain`` (cm, rad; single robot) with ``robot``'s names and
    limits. ``comment`` (plain text) goes at the top: which model, which frame."""
    origins = joint_origins(chain)
    links = link_names(robot)
    lines = [
        '<?xml version="1.0"?>',
        f"<!-- {comment.replace('--', '-')} -->",
        f"<robot name={quoteattr(name)}>",
        *(f"  <link name={quoteattr(link)}/>" for link in links),
    ]
    for i, j in enumerate(robot.joints):
        lo, hi = (
            (j.lower * M_PER_CM, j.upper * M_PER_CM)
            if j.prismatic
            else np.radians((j.lower, j.upper))
        )
        lines += [
            f"  <joint name={quoteattr(j.name)} type={quoteattr(j.type)}>",
            f"    <parent link={quoteattr(links[i])}/>",
            f"    <child link={quoteattr(links[i + 1])}/>",
            f"    {_origin(origins[i])}",
            '    <axis xyz="0 0 1"/>',
            # armsig knows no effort or velocity limits; urdfdom requires the attributes.
            f'    <limit lower="{_num(lo)}" upper="{_num(hi)}" effort="0" velocity="0"/>',
            "  </joint>",
        ]
    lines += [
        f'  <joint name={quoteattr(TOOL_JOINT)} type="fixed">',
        f"    <parent link={quoteattr(links[-2])}/>",
        f"    <child link={quoteattr(links[-1])}/>",
        f"    {_origin(origins[-1])}",
        "  </joint>",
        "</robot>",
    ]
    return "\n".join(lines) + "\n"


def chain_from_origins(origins_cm: Array, prismatic: Array) -> SerialChain:
    """The URDF's kinematics as a chain (cm; joint variable = reading): for checking it."""
    return SerialChain(origins_cm[1:], prismatic, origins_cm[0], np.eye(4))


def written_origins(chain: SerialChain) -> Array:
    """The joint origins as the URDF text states them (xyz, rpy rounded to its doubles), cm."""
    xyz, rpy = xyz_rpy_from_transform(joint_origins(chain))
    out: Array = transform_from_xyz_rpy((xyz * M_PER_CM) / M_PER_CM, rpy)
    return out
