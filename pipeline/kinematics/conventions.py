"""Reading conventions between two chains of one robot: ``q_b = s · q_a + c`` per joint.

Two descriptions of one arm (armsig's design model and a vendor's URDF) may count a joint
the other way round (``s = −1``) or from another zero (``c``). With frames ``A_i(q)`` and
``B_i(q)`` of the two chains (z on joint ``i+1``'s axis, :func:`pipeline.kinematics.chain.
link_frames`), they are one robot when ``B_i(s q + c) = W · A_i(q) · E_i`` for a constant
world change ``W`` and constant ``E_i``. Since both frames have z on the same axis, ``E_i``
turns about and slides along z, after a half turn about x where the next joint counts the
other way: ``E_i = Flip(s_{i+1}) · Rot(z, φ_i) · Trans(z, t_i)``. With the chain recursion
(5.1)-(5.3) this gives, joint by joint,

    E_i = K̄a_i⁻¹ · Flip(s_i) · Rot(z, ψ) · Trans(z, t) · K̄b_i,
    ψ = s_i q0a_i + φ_{i−1} + c_i − q0b_i            (revolute joint i)

so ``c_i`` (with ``s_{i+1}``) is the turn ``ψ`` about joint ``i``'s axis that lays chain
``b``'s next axis ``K̄b_i · z`` onto chain ``a``'s ``Flip(s_i) · K̄a_i · z`` (a slide ``t``
along the axis is free here; the fit of the whole chain sets it). The first joint's
``s, c`` and the last joint's ``c`` are conventions of ``W`` and of the last frame: 1 and 0.
A prismatic joint's ``c`` slides along its axis like ``t``: it is left at 0 here, and a
vendor zero elsewhere shows in the fit of the whole chain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import Array, rot_x, wrap_angle

#: Two axis directions are one when they differ by less than this (rad): a vendor file's
#: rounded π/2 (1.57079632679) is 5e-12 off; a different robot is degrees off.
SAME_DIRECTION_RAD = 1e-6
#: Two axis lines are one when they pass within this (cm) of each other: 1e-6 m, the
#: acceptance of the vendor check (docs/export.md); a different robot is centimetres off.
SAME_LINE_CM = 1e-4


@dataclass(frozen=True)
class Conventions:
    """``q_b = sign · q_a + offset`` per joint (rad / cm)."""

    sign: Array
    offset: Array


@dataclass(frozen=True)
class _Candidate:
    sign: float  # the next joint's sign
    psi: float  # the turn about this joint's axis (nan: any)
    miss_rad: float  # the directions left apart
    miss_cm: float  # the lines left apart


def _flip(s: float) -> Array:
    out: Array = rot_x(np.pi) if s < 0 else np.eye(4)
    return out


def _rz(psi: float) -> Array:
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _lay(p: Array, u: Array, r: Array, w: Array, psi: float | None) -> list[_Candidate]:
    """Turns ``ψ`` about z (with any slide along z) laying the line ``p + λu`` onto
    ``r + λw`` (directions ±), each with what is left apart; ``psi`` given: that turn only."""
    if abs(u[2]) > np.cos(SAME_DIRECTION_RAD):  # the line is parallel to z
        if abs(w[2]) <= np.cos(SAME_DIRECTION_RAD):
            return [_Candidate(1.0, 0.0, float(np.arccos(min(abs(w[2]), 1.0))), 0.0)]
        s = float(np.sign(u[2] * w[2]))
        if psi is None:  # the turn that takes p's foot on the xy plane to r's
            if max(np.hypot(*p[:2]), np.hypot(*r[:2])) <= SAME_LINE_CM:
                return [_Candidate(s, np.nan, 0.0, 0.0)]  # both on z itself: any turn
            psi = float(np.arctan2(r[1], r[0]) - np.arctan2(p[1], p[0]))
        miss = np.linalg.norm((_rz(psi) @ p - r)[:2])
        return [_Candidate(s, psi, 0.0, float(miss))]
    out = []
    for s in (1.0, -1.0):
        v = s * w
        turn = np.arctan2(u[0] * v[1] - u[1] * v[0], u[0] * v[0] + u[1] * v[1])
        t = float(turn) if psi is None else psi
        R = _rz(t)
        gap = float(np.arcsin(min(np.linalg.norm(np.cross(R @ u, v)), 1.0)))
        if np.dot(R @ u, v) < 0:
            gap = np.pi - gap
        d = R @ p - r  # the slide along z that brings the lines closest, then their gap
        e = np.cross([0.0, 0.0, 1.0], w)
        if gap > SAME_DIRECTION_RAD or not np.dot(e, e) > 0.0:
            out.append(_Candidate(s, t, gap, np.inf))
            continue
        slide = -np.dot(np.cross(d, w), e) / np.dot(e, e)
        miss = float(np.linalg.norm(np.cross(d + np.array([0.0, 0.0, slide]), w)))
        out.append(_Candidate(s, t, gap, miss))
    return out


def reading_conventions(a: SerialChain, b: SerialChain, names: list[str]) -> Conventions:
    """``sign``, ``offset`` with ``q_b = sign · q_a + offset`` that make chain ``b`` the same
    robot as chain ``a`` (module docstring), or :class:`KinematicsError` naming the joint
    whose axis does not fit (``names``: the joints' names, for the message).

    Where two turns fit (the next axis crosses this one at a right angle: a turn, and a
    half turn more with the next joint counted the other way, are the same geometry), the
    one with the offset nearest 0 is taken, then the one that keeps the next sign.
    """
    n = a.n_joints
    if b.n_joints != n or not np.array_equal(a.prismatic, b.prismatic):
        raise KinematicsError(
            "the two descriptions' joints differ in number or type",
            expected=", ".join(f"{x} ({'prismatic' if p else 'revolute'})"
                               for x, p in zip(names, a.prismatic, strict=True)),
        )  # fmt: skip
    sign, offset = np.ones(n), np.zeros(n)
    phi = 0.0  # E_{i−1}'s turn about z
    qa, qb = a.joint_offsets, b.joint_offsets
    for i in range(n - 1):
        A, B = _flip(sign[i]) @ a.links[i], b.links[i]
        fixed = phi if i > 0 and a.prismatic[i] else None  # a slide keeps the turn
        cands = _lay(B[:3, 3], B[:3, 2], A[:3, 3], A[:3, 2], fixed)

        def c_of(k: _Candidate, i: int = i) -> float:
            if i == 0 or a.prismatic[i] or np.isnan(k.psi):
                return 0.0  # conventions: the world's turn, a slide's zero, any turn
            return float(wrap_angle(k.psi - sign[i] * qa[i] - phi + qb[i]))

        good = [k for k in cands if k.miss_rad <= SAME_DIRECTION_RAD and k.miss_cm <= SAME_LINE_CM]
        if not good:
            worst = min(cands, key=lambda k: (k.miss_rad, k.miss_cm))
            raise KinematicsError(
                f"joint {names[i + 1]}'s axis is not where the other description puts it "
                f"relative to joint {names[i]}'s",
                got=f"{np.degrees(worst.miss_rad):.3g} deg and {worst.miss_cm * 10:.3g} mm apart",
                fix="check that both describe the same robot model",
            )
        k = min(good, key=lambda k: (round(abs(c_of(k)), 9), -k.sign))
        psi = k.psi
        if np.isnan(psi):  # any turn: the one that keeps the reading's zero (c = 0)
            psi = 0.0 if i == 0 else float(sign[i] * qa[i] + phi - qb[i])
        offset[i] = c_of(_Candidate(k.sign, psi, 0.0, 0.0))
        sign[i + 1] = k.sign
        # E_i = K̄a_i⁻¹ Flip(s_i) Rot(z, ψ) K̄b_i (rotations) = Flip(s_{i+1}) Rot(z, φ_i)
        E = a.links[i][:3, :3].T @ _flip(sign[i])[:3, :3] @ _rz(psi) @ B[:3, :3]
        E = _flip(sign[i + 1])[:3, :3] @ E
        phi = float(np.arctan2(E[1, 0], E[0, 0]))
    return Conventions(sign, offset)
