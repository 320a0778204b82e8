"""JSON documents of the exports ``dh``, ``mdh`` and ``json`` (docs/export.md), and the
chain read back from the last.

Boundary units: lengths in cm, angles in degrees, the unit in every key; matrices are
4 × 4 row-major with translations in cm. Every document states its convention.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.dh_table import HAYATI_DEG, DHTable, ModifiedDHTable
from pipeline.robots.description import RobotDescription
from pipeline.signature.file import matrix_rows
from pipeline.units import joints_to_boundary, joints_to_internal

DH_CONVENTION = (
    "A_i = Rot(z, theta_i) Trans(0, 0, d_i) Trans(a_i, 0, 0) Rot(x, alpha_i) Rot(y, beta_i); "
    "T(q) = base A_1 ... A_n tool; revolute: theta_i = q_i + theta_deg, "
    "prismatic: d_i = q_i + d_cm (q = encoder reading, deg / cm)"
)
MDH_CONVENTION = (
    "A_i = Rot(x, alpha_prev_i) Trans(a_prev_i, 0, 0) Rot(y, beta_prev_i) Rot(z, theta_i) "
    "Trans(0, 0, d_i) (Craig's modified D-H, beta after Hayati); T(q) = base A_1 ... A_n tool; "
    "revolute: theta_i = q_i + theta_deg, prismatic: d_i = q_i + d_cm "
    "(q = encoder reading, deg / cm)"
)
CHAIN_CONVENTION = (
    "T(q) = base K_1 ... K_n tool, K_i = Rot(z, q_i - q0_i) links_i (revolute) or "
    "Trans(0, 0, q_i - q0_i) links_i (prismatic); q = encoder reading, deg / cm; "
    "q0 = joint_offsets"
)
HAYATI_NOTE = (
    f"beta is Hayati's parameter: rows whose joint axes are within {HAYATI_DEG:g} deg of "
    "parallel place their frame where the next axis crosses the plane through the previous "
    "frame's origin normal to this axis (d = 0 there, beta tilts the axis) instead of on the "
    "far common normal (a prismatic joint's row keeps the next S-Model frame's origin, d "
    "being its variable); other rows are classic D-H (beta = 0). Prismatic lines are moved "
    "onto the next joint axis first (armsig Section 4.3.5)"
)


def _header(robot: RobotDescription, model: str, frame: str, convention: str) -> dict[str, Any]:
    return {
        "format": "armsig-export",
        "robot": robot.name,
        "model": model,
        "frame": frame,
        "length_unit": "cm",
        "angle_unit": "deg",
        "convention": convention,
    }


def _joint(robot: RobotDescription, i: int) -> dict[str, Any]:
    j = robot.joints[i]
    return {"joint": j.name, "type": j.type, f"limits_{j.unit}": [j.lower, j.upper]}


def _table(
    head: dict[str, Any], base: np.ndarray, rows: list[dict[str, Any]], tool: np.ndarray
) -> dict[str, Any]:
    """A D-H table document: header, Hayati's note, base (4, 4), rows, tool (4, 4)."""
    return {
        **head,
        "note": HAYATI_NOTE,
        "base": matrix_rows(base),
        "rows": rows,
        "tool": matrix_rows(tool),
    }


def dh_document(t: DHTable, robot: RobotDescription, model: str, frame: str) -> dict[str, Any]:
    """The standard D-H table with Hayati's β as a JSON-ready dict."""
    rows = [
        {
            **_joint(robot, i),
            "theta_deg": float(np.degrees(t.theta[i])),
            "d_cm": float(t.d[i]),
            "a_cm": float(t.a[i]),
            "alpha_deg": float(np.degrees(t.alpha[i])),
            "beta_deg": float(np.degrees(t.beta[i])),
            "hayati": bool(t.hayati[i]),
        }
        for i in range(robot.n_joints)
    ]
    return _table(_header(robot, model, frame, DH_CONVENTION), t.base, rows, t.tool)


def mdh_document(
    m: ModifiedDHTable, hayati: np.ndarray, robot: RobotDescription, model: str, frame: str
) -> dict[str, Any]:
    """Craig's modified D-H table with Hayati's β as a JSON-ready dict."""
    rows = [
        {
            **_joint(robot, i),
            "alpha_prev_deg": float(np.degrees(m.alpha_prev[i])),
            "a_prev_cm": float(m.a_prev[i]),
            "beta_prev_deg": float(np.degrees(m.beta_prev[i])),
            "theta_deg": float(np.degrees(m.theta[i])),
            "d_cm": float(m.d[i]),
            "hayati_prev": bool(i > 0 and hayati[i - 1]),
        }
        for i in range(robot.n_joints)
    ]
    return _table(_header(robot, model, frame, MDH_CONVENTION), m.base, rows, m.tool)


def chain_document(
    chain: SerialChain, robot: RobotDescription, model: str, frame: str
) -> dict[str, Any]:
    """The serial chain (5.1)-(5.3) as plain matrices."""
    head = _header(robot, model, frame, CHAIN_CONVENTION)
    q0 = joints_to_boundary(np.asarray(chain.joint_offsets), robot.prismatic)
    return {
        **head,
        "joints": [_joint(robot, i) for i in range(robot.n_joints)],
        "joint_offsets": [float(v) for v in q0],
        "base": matrix_rows(chain.base),
        "links": [matrix_rows(L) for L in chain.links],
        "tool": matrix_rows(chain.tool),
    }


def chain_from_document(doc: dict[str, Any], prismatic: np.ndarray) -> SerialChain:
    """The chain a :func:`chain_document` (as read back) describes: for checking it."""
    q0 = joints_to_internal(doc["joint_offsets"], prismatic)
    return SerialChain(np.array(doc["links"]), prismatic, np.array(doc["base"]),
                       np.array(doc["tool"]), q0)  # fmt: skip
