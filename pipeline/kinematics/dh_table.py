"""D-H and modified (Craig) D-H tables of a serial chain, with Hayati's β on nearly
parallel axes (format in docs/export.md).

Standard row ``i`` (Section 2.2.1, plus Hayati's rotation about y)::

    A_i = Rot(z, θ_i) · Trans(0, 0, d_i) · Trans(a_i, 0, 0) · Rot(x, α_i) · Rot(y, β_i)
    T(q) = base · A_1 ⋯ A_n · tool

with ``θ_i = q_i + θ_offset_i`` (revolute) or ``d_i = q_i + d_offset_i`` (prismatic), ``q``
the encoder reading. Frame ``T_i`` has its z axis on joint ``i+1``'s axis. Where the axes of
joints ``i`` and ``i+1`` are skew by more than :data:`HAYATI_DEG`, ``T_i`` sits on their common
normal and ``β_i = 0`` (classic D-H). Where they are within :data:`HAYATI_DEG` of parallel
(or anti-parallel), the common normal is far away or undefined (the convergence-angle
blow-up: ``d`` of order ``offset / sin(angle)``), and Hayati's rule places ``T_i`` where
axis ``i+1`` crosses the plane through ``T_{i−1}``'s origin normal to axis ``i``: ``d_i = 0``
there (at the signature reading, for a prismatic joint), and ``α_i``, ``β_i`` tilt the axis.

Modified (Craig) row ``i``, from the same frames regrouped::

    A'_i = Rot(x, α_{i−1}) · Trans(a_{i−1}, 0, 0) · Rot(y, β_{i−1}) · Rot(z, θ_i) · Trans(0, 0, d_i)

with ``α_0 = a_0 = β_0 = 0``; the standard row's tail ``Trans(a_n) Rot(x, α_n) Rot(y, β_n)``
moves into the tool.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.kinematics.dh import dh_link
from pipeline.kinematics.smodel import PARALLEL_TOL, matrix_from_smodel, smodel_from_matrix
from pipeline.kinematics.transforms import (
    Array,
    invert_transform,
    rot_x,
    rot_y,
    rot_z,
    trans_x,
    trans_z,
    wrap_angle,
)
from pipeline.kinematics.true_dh import relocate_prismatic

#: Axes within this angle of parallel get Hayati's β instead of a common normal. Beyond it,
#: |d| ≤ (distance between the axes) / sin(10°) ≈ 5.8 × that distance; below it |β| ≤ 10°,
#: far from Hayati's own singularity at perpendicular axes.
HAYATI_DEG = 10.0

#: Where the next axis crosses within this distance of the previous frame's origin (cm), the
#: crossing counts as the origin itself (``a = 0``, θ chosen for ``β = 0``) instead of giving
#: θ the direction of a round-off vector; 1e-9 cm = 1e-11 m, below the export's 1e-9 m.
COINCIDENT_CM = 1e-9


@dataclass(frozen=True)
class DHTable:
    """Standard rows (radians, cm), arrays of shape (n,), plus base and tool (4, 4), cm.

    ``theta`` / ``d`` hold the value at encoder reading 0: the offset added to the
    reading for the joint's variable (``theta`` of a revolute, ``d`` of a prismatic joint).
    """

    theta: Array
    d: Array
    a: Array
    alpha: Array
    beta: Array
    prismatic: Array
    base: Array
    tool: Array

    @property
    def hayati(self) -> Array:
        """Rows placed by Hayati's rule (nearly parallel axes), bool (n,)."""
        out: Array = np.abs(np.sin(self.alpha)) < np.sin(np.radians(HAYATI_DEG))
        return out


def _hayati_row(B: Array, z0: float) -> tuple[float, float, float, float]:
    """``(θ, a, α, β)`` of ``Rot(z,θ) Trans(0,0,z0) Trans(a,0,0) Rot(x,α) Rot(y,β)`` whose
    origin is where the z line of ``B`` (4, 4) crosses the plane z = ``z0``, and whose z
    axis is ``B``'s."""
    u, p = B[:3, 2], B[:3, 3]
    o = p - ((p[2] - z0) / u[2]) * u  # axis i+1 meets z = z0 (|u_z| ≥ cos 10°)
    theta = float(np.arctan2(o[1], o[0]))
    a = float(np.hypot(o[0], o[1]))
    if a < COINCIDENT_CM:  # the axes meet there: θ is free; tilt about x alone (β = 0)
        a = 0.0
        tilted = np.hypot(u[0], u[1]) >= PARALLEL_TOL
        theta = float(np.arctan2(-u[0], u[1])) if tilted else 0.0
    c, s = np.cos(theta), np.sin(theta)
    ux, uy = c * u[0] + s * u[1], -s * u[0] + c * u[1]  # u in Rot(z, θ)'s frame
    # Rot(x,α) Rot(y,β) e_z = (sin β, −sin α cos β, cos α cos β)
    alpha = float(np.arctan2(-uy, u[2]))
    beta = float(np.arctan2(ux, np.hypot(uy, u[2])))
    return theta, a, alpha, beta


def relocated(chain: SerialChain) -> SerialChain:
    """``chain`` with every prismatic joint's line moved onto the next joint's axis
    (Section 4.3.5, :func:`pipeline.kinematics.true_dh.relocate_prismatic`): the S-Model
    puts it through the targets, an arbitrary line parallel to the travel."""
    if not chain.prismatic.any():
        return chain
    sm, base = relocate_prismatic(smodel_from_matrix(chain.links), chain.prismatic, chain.base)
    links = matrix_from_smodel(sm.beta, sm.d_bar, sm.a_bar, sm.alpha_bar, sm.gamma, sm.b)
    return SerialChain(links, chain.prismatic, base, chain.tool, chain.joint_offsets)


def row_matrix(theta: float, d: float, a: float, alpha: float, beta: float) -> Array:
    """Standard row ``A = Rot(z,θ) Trans(0,0,d) Trans(a,0,0) Rot(x,α) Rot(y,β)``, (4, 4)."""
    out: Array = dh_link(theta, d, a, alpha) @ rot_y(beta)
    return out


def dh_table_from_chain(chain: SerialChain) -> DHTable:
    """The D-H table of a single-robot chain, reproducing ``forward_kinematics(chain, q)``.

    The frames are those of the chain (prismatic lines :func:`relocated`) at its signature
    reading ``q = joint_offsets`` (every joint motion the identity), walked from the base:
    each new frame from the previous one and the next joint axis, each value taken
    relative to the reading. A prismatic joint's Hayati frame keeps the next S-Model
    frame's origin (its ``d`` is the joint's variable, so the plane ``d = 0`` of a
    revolute joint has no meaning there).
    """
    chain = relocated(chain)
    n = chain.n_joints
    q0 = np.asarray(chain.joint_offsets, float)
    F = link_frames(chain, q0)  # F[i]: z on axis i+1 (F[n]: the last link frame)
    pris = np.asarray(chain.prismatic, bool)
    vals = np.zeros((5, n))  # θ, d, a, α, β at the reading q0
    T = np.array(chain.base, float)  # T_0 = F_0
    parallel = np.cos(np.radians(HAYATI_DEG))
    for i in range(n):
        B = invert_transform(T) @ F[i + 1]  # axis i+1 (F's z) in T_{i−1}
        if abs(B[2, 2]) >= parallel:  # nearly (anti-)parallel: Hayati
            d = float(B[2, 3]) if pris[i] else 0.0
            theta, a, alpha, beta = _hayati_row(B, d)
        else:  # common normal: (3.12)-(3.15) with γ, b of this link left to the next row
            sm = smodel_from_matrix(B)
            theta, d, a, alpha, beta = (
                float(sm.beta), float(sm.d_bar), float(sm.a_bar), float(sm.alpha_bar), 0.0,
            )  # fmt: skip
        vals[:, i] = theta, d, a, alpha, beta
        T = T @ row_matrix(theta, d, a, alpha, beta)
    tool = invert_transform(T) @ F[n] @ chain.tool
    theta, d = vals[0].copy(), vals[1].copy()
    theta[~pris] = wrap_angle(theta[~pris] - q0[~pris])  # θ_i = q_i + θ_offset_i
    d[pris] = d[pris] - q0[pris]  # d_i = q_i + d_offset_i
    return DHTable(theta, d, vals[2], vals[3], vals[4], pris, np.array(chain.base), tool)


def chain_from_dh_table(t: DHTable) -> SerialChain:
    """The table as a :class:`SerialChain` (joint offsets 0): for checking it."""
    links = np.stack([row_matrix(*v) for v in zip(t.theta, t.d, t.a, t.alpha, t.beta, strict=True)])
    return SerialChain(links, t.prismatic, t.base, t.tool)


@dataclass(frozen=True)
class ModifiedDHTable:
    """Craig's rows: ``alpha_prev``, ``a_prev``, ``beta_prev`` (of row i−1) and ``theta``,
    ``d`` of joint i; radians and cm, arrays (n,); base and tool (4, 4), cm."""

    alpha_prev: Array
    a_prev: Array
    beta_prev: Array
    theta: Array
    d: Array
    prismatic: Array
    base: Array
    tool: Array


def modified_from_dh(t: DHTable) -> ModifiedDHTable:
    """Regroup standard rows into Craig's: ``Trans(a,0,0)`` and ``Rot(x,α)`` commute."""
    alpha, a, beta = (np.concatenate(([0.0], v[:-1])) for v in (t.alpha, t.a, t.beta))
    tail = trans_x(t.a[-1]) @ rot_x(t.alpha[-1]) @ rot_y(t.beta[-1])
    return ModifiedDHTable(alpha, a, beta, t.theta, t.d, t.prismatic, t.base, tail @ t.tool)


def chain_from_modified(m: ModifiedDHTable) -> SerialChain:
    """Craig's table as a :class:`SerialChain`: ``base · P_1``, links ``Q_i · P_{i+1}``."""
    P = rot_x(m.alpha_prev) @ trans_x(m.a_prev) @ rot_y(m.beta_prev)  # (n, 4, 4)
    Q = rot_z(m.theta) @ trans_z(m.d)
    links = Q.copy()
    links[:-1] = Q[:-1] @ P[1:]
    return SerialChain(links, m.prismatic, m.base @ P[0], m.tool)
