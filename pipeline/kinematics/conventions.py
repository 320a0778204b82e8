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

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import Array, invert_transform, rot_x, wrap_angle

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
    world: Array  # (4, 4): chain b's world in chain a's, W
    alternatives: int = 0  # other conventions the geometry fits as well


@dataclass(frozen=True)
class _Candidate:
    sign: float  # the next joint's sign
    psi: float  # the turn about this joint's axis (nan: any)
    slide: float | None  # the slide along it (None: any, the axes being parallel)
    miss_rad: float  # the directions left apart
    miss_cm: float  # the lines left apart


def _flip(s: float) -> Array:
    out: Array = rot_x(np.pi) if s < 0 else np.eye(4)
    return out


def _rz(psi: float) -> Array:
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _lay(
    p: Array, u: Array, r: Array, w: Array, psi: float | None, slide: float | None
) -> list[_Candidate]:
    """Turns ``ψ`` about and slides along z laying the line ``p + λu`` onto ``r + λw``
    (directions ±), each with what is left apart; a given ``psi`` or ``slide`` is kept."""
    if abs(u[2]) > np.cos(SAME_DIRECTION_RAD):  # parallel to z: any slide, one turn
        if abs(w[2]) <= np.cos(SAME_DIRECTION_RAD):
            return [_Candidate(1.0, 0.0, slide, float(np.arccos(min(abs(w[2]), 1.0))), 0.0)]
        s = float(np.sign(u[2] * w[2]))
        if psi is None:  # the turn that takes p's foot on the xy plane to r's
            if max(np.hypot(*p[:2]), np.hypot(*r[:2])) <= SAME_LINE_CM:
                return [_Candidate(s, np.nan, slide, 0.0, 0.0)]  # both on z itself: any turn
            psi = float(np.arctan2(r[1], r[0]) - np.arctan2(p[1], p[0]))
        apart = float(np.linalg.norm((_rz(psi) @ p - r)[:2]))
        return [_Candidate(s, psi, slide, 0.0, apart)]
    out = []
    for s in (1.0, -1.0):
        v = s * w
        turn = np.arctan2(u[0] * v[1] - u[1] * v[0], u[0] * v[0] + u[1] * v[1])
        t = float(turn) if psi is None else psi
        R = _rz(t)
        gap = float(np.arccos(np.clip(np.dot(R @ u, v), -1.0, 1.0)))
        d = R @ p - r  # the slide along z that brings the lines closest, then their gap
        e = np.cross([0.0, 0.0, 1.0], w)
        if gap > SAME_DIRECTION_RAD or not np.dot(e, e) > 0.0:
            out.append(_Candidate(s, t, slide, gap, np.inf))
            continue
        z: float = float(-np.dot(np.cross(d, w), e) / np.dot(e, e)) if slide is None else slide
        miss = float(np.linalg.norm(np.cross(d + np.array([0.0, 0.0, z]), w)))
        out.append(_Candidate(s, t, z, gap, miss))
    return out


def reading_conventions(a: SerialChain, b: SerialChain, names: list[str]) -> Conventions:
    """``sign``, ``offset`` with ``q_b = sign · q_a + offset`` that make chain ``b`` the same
    robot as chain ``a`` (module docstring), or :class:`KinematicsError` naming the joint
    whose axis does not fit (``names``: the joints' names, for the message).

    Where the next axis crosses this one at a right angle, a turn and a half turn more
    with the next joint counted the other way lay the same pair of lines; the geometry
    alone may then fit several conventions to the end. The one with the fewest reversed
    joints, then the smallest offsets, is returned (``alternatives``: how many others fit).
    """
    n = a.n_joints
    if b.n_joints != n or not np.array_equal(a.prismatic, b.prismatic):
        raise KinematicsError(
            "the two descriptions' joints differ in number or type",
            expected=", ".join(f"{x} ({'prismatic' if p else 'revolute'})"
                               for x, p in zip(names, a.prismatic, strict=True)),
        )  # fmt: skip
    misfit: list[tuple[int, _Candidate]] = []
    found = list(_search(a, b, 0, np.eye(4), _Slide(1.0), np.ones(n), np.zeros(n + 2), misfit))
    if not found:
        i, worst = max(misfit, key=lambda m: m[0])  # the joint the search got furthest to
        raise KinematicsError(
            f"joint {names[i + 1]}'s axis is not where the other description puts it "
            f"relative to joint {names[i]}'s",
            got=f"{np.degrees(worst.miss_rad):.3g} deg and {worst.miss_cm * 10:.3g} mm apart",
            fix="check that both describe the same robot model",
        )
    sign, off = min(
        found, key=lambda f: (int((f[0] < 0).sum()), round(float(np.abs(f[1][:n]).sum()), 9))
    )
    # E_{-1} = Rot(z, ψ_0) Trans(z, slide_0): b.base = W · a.base · E_{-1}
    E = np.eye(4)
    E[:3, :3], E[2, 3] = _rz(off[n + 1]), off[n]
    world = b.base @ invert_transform(E) @ invert_transform(a.base)
    return Conventions(sign, off[:n], world, len(found) - 1)


@dataclass(frozen=True)
class _Slide:
    """``E_{i−1}``'s slide along z while parallel axes leave it open: ``t0 + alpha · τ``
    with ``τ`` unknown, and the offsets of prismatic joints that wait for it:
    ``offset[j] = c0 + beta · τ`` for each ``(j, c0, beta)``."""

    alpha: float
    pending: tuple[tuple[int, float, float], ...] = ()


def _settle(offset: Array, slide: _Slide | None, tau: float) -> None:
    """The waiting offsets at ``τ`` (``offset[n]``: the world's slide along joint 1)."""
    for j, c0, beta in slide.pending if slide else ():
        offset[j] = c0 + beta * tau


def _search(a: SerialChain, b: SerialChain, i: int, E: Array, slide: _Slide | None,
            sign: Array, offset: Array, misfit: list[tuple[int, _Candidate]]
            ) -> Iterator[tuple[Array, Array]]:  # fmt: skip
    """Every ``(sign, offset)`` that fits from joint ``i`` on, depth first (``E``:
    ``E_{i−1}`` at ``τ = 0``, ``slide``: its open slide, None when fixed; ``sign[:i+1]``
    and the settled ``offset[:i]`` set); a dead end notes its misfit."""
    n = a.n_joints
    if i >= n - 1:  # the last joint's offset is the last frame's convention
        _settle(offset, slide, 0.0)  # a slide never fixed: the world's along the axes
        offset[n - 1] = 0.0
        yield sign.copy(), offset.copy()
        return
    F = _flip(sign[i]) @ E  # Rot(z, φ) Trans(z, t0 + α τ)
    phi, t0 = float(np.arctan2(F[1, 0], F[0, 0])), float(F[2, 3])
    A, B = _flip(sign[i]) @ a.links[i], b.links[i]
    pris = bool(a.prismatic[i])
    # revolute: ψ = s q0a + φ + c − q0b, the slide t goes through; prismatic: the turn φ
    # goes through, the slide is t + s q0a + c − q0b (joint 1: the world's turn and slide)
    given = None if pris or slide is not None else t0
    cands = _lay(B[:3, 3], B[:3, 2], A[:3, 3], A[:3, 2], phi if pris and i > 0 else None, given)
    good = [k for k in cands if k.miss_rad <= SAME_DIRECTION_RAD and k.miss_cm <= SAME_LINE_CM]
    if not good:
        misfit.append((i, min(cands, key=lambda k: (k.miss_rad, k.miss_cm))))
        return
    qa, qb = np.asarray(a.joint_offsets), np.asarray(b.joint_offsets)
    shift = float(sign[i] * qa[i] - qb[i])
    along = float(B[2, 2])  # next axis parallel: a slide before is ±one after
    for k in good:
        psi = k.psi
        if np.isnan(psi):  # any turn: the one that keeps the reading's zero
            psi = 0.0 if i == 0 else float(phi + shift)
        out: _Slide | None = None
        z = t0 if k.slide is None else k.slide
        if i == 0:
            offset[i] = 0.0  # the world's turn about and slide along joint 1 instead:
            offset[n + 1], offset[n] = psi, z  # kept after the joints' offsets
            out = None if k.slide is not None else _Slide(along, ((n, 0.0, 1.0),))
        elif not pris:
            offset[i] = float(wrap_angle(psi - phi - shift))
            if slide is not None and k.slide is not None:  # the open slide is fixed here
                _settle(offset, slide, (k.slide - t0) / slide.alpha)
            elif slide is not None:
                out = _Slide(slide.alpha * along, slide.pending)
        elif k.slide is not None:  # the slide is fixed here: with it, this joint's zero
            _settle(offset, slide, 0.0)
            offset[i] = k.slide - t0 - shift
        elif slide is None:  # its zero waits for a later axis: c = τ
            offset[i], z = 0.0, t0 + shift
            out = _Slide(along, ((i, 0.0, 1.0),))
        else:  # open before and after: the world's slide, this zero with it
            offset[i], z = 0.0, t0 + shift
            out = _Slide(slide.alpha * along, slide.pending)
        sign[i + 1] = k.sign
        # E_i = K̄a_i⁻¹ Flip(s_i) Rot(z, ψ) Trans(z, slide) K̄b_i
        M = np.eye(4)
        M[:3, :3], M[2, 3] = _rz(psi), z
        E_i = invert_transform(a.links[i]) @ _flip(sign[i]) @ M @ B
        yield from _search(a, b, i + 1, E_i, out, sign, offset, misfit)
