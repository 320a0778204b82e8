"""Puma 560: simulator model (7.1)-(7.8), Table 6-2, Appendix B forward and inverse.

Design model
    The built-in ``puma560`` description is model (7.1) with every ε = 0, which
    equals a D-H chain (ERRATA.md). Table 6-2 (:data:`TABLE_6_2`) differs in
    two entries: ``d4 = 43.307`` (design model: 43.37 = x8 + x11 of Table 7-2)
    and ``d6 = 0`` (Table 6-2 ends at the wrist centre; the design model at the
    flange, 5.715 = x14 + x15). Table 6-2 also puts frame 0 at the shoulder
    (``d1 = 0``), the design model on the mounting surface (``d1 = 67.4``).

Inverse
    :func:`inverse_kinematics` is the closed form of Appendix B.2 derived anew
    for the design chain (the print is garbled; ERRATA.md reads θ3 with
    ``r2²``). It returns all eight solutions with their branch flags.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import (
    Array,
    ArrayLike,
    chain_product,
    invert_transform,
    rot_x,
    rot_y,
    rot_z,
    trans,
    trans_z,
    wrap_angle,
)

#: Table 7-2: nominal design parameters x1..x15 (cm, or degrees for x3, x10, x12, x13).
X_NOMINAL = np.array(
    [
        58.5,
        8.9,
        -90.0,
        17.75,
        2.5,
        43.18,
        -2.032,
        -33.32,
        -5.341,
        90.0,
        10.05,
        -90.0,
        90.0,
        4.445,
        1.27,
    ]
)
_X_ANGULAR = {3, 10, 12, 13}

#: ERRATA.md: the ε categories of (7.2)-(7.8), 1-based indices.
EPS_ENCODER = (8, 14, 21, 30, 34, 38)
EPS_POSITIONAL = (1, 2, 3, 9, 12, 15, 18, 22, 25, 26, 27, 31, 32, 35, 37, 39)
EPS_ORIENTATIONAL = (4, 5, 6, 7, 10, 11, 13, 16, 17, 19, 20, 23, 24, 28, 29, 33, 36)
N_EPS = 39

#: Table 6-2 (d, a in cm; α in degrees), θ variable with zero offset.
TABLE_6_2 = {
    "d_cm": (0.0, 14.909, 0.0, 43.307, 0.0, 0.0),
    "a_cm": (0.0, 43.18, -2.032, 0.0, 0.0, 0.0),
    "alpha_deg": (-90.0, 0.0, 90.0, -90.0, 90.0, 0.0),
}

#: Design D-H chain = model (7.1) at ε = 0 (ERRATA.md).
DESIGN_D_CM = (67.4, 14.909, 0.0, 43.37, 0.0, 5.715)
DESIGN_A_CM = (0.0, 43.18, -2.032, 0.0, 0.0, 0.0)
DESIGN_ALPHA_DEG = (-90.0, 0.0, 90.0, -90.0, 90.0, 0.0)


def simulator_chain(eps: ArrayLike | None = None) -> SerialChain:
    """Model (7.1)-(7.8) of a manufactured Puma 560 as a serial chain.

    Parameters
    ----------
    eps : array_like, shape (..., 39), optional
        Manufacturing errors ε1..ε39 in *math units*: cm for the positional
        ones, radians for the orientational and encoder ones (see
        :data:`EPS_POSITIONAL` etc.). A leading batch shape gives a batch of
        robots (links of shape (..., 6, 4, 4)). ``None`` means ε = 0.

    Returns
    -------
    SerialChain
        ``base = K0``, ``links[i] = K̄_{i+1}`` with ``K_i = Rot(z, θ_i) K̄_i``.
    """
    e = np.zeros(N_EPS) if eps is None else np.asarray(eps, float)
    E = [e[..., k] for k in range(N_EPS)]  # E[k-1] is ε_k
    x = [
        np.deg2rad(v) if k + 1 in _X_ANGULAR else v for k, v in enumerate(X_NOMINAL)
    ]  # x[k-1] is x_k

    def eps_(k: int) -> Array:
        return E[k - 1]

    def x_(k: int) -> float:
        return float(x[k - 1])

    K0 = chain_product(  # Eq. (7.2)
        trans(eps_(1), eps_(2), eps_(3)),
        rot_x(eps_(4)),
        rot_y(eps_(5)),
        trans_z(x_(1)),
        rot_x(eps_(6)),
        rot_y(eps_(7)),
        rot_z(eps_(8)),
    )
    K1 = chain_product(  # Eq. (7.3), after Rot(z, θ1)
        trans_z(eps_(9)),
        rot_x(eps_(10)),
        rot_y(eps_(11)),
        trans(eps_(12), 0.0, x_(2)),
        rot_x(eps_(13) + x_(3)),
        trans_z(x_(4)),
        rot_z(eps_(14)),
    )
    K2 = chain_product(  # Eq. (7.4), after Rot(z, θ2)
        trans_z(eps_(15) + x_(5)),
        rot_x(eps_(16)),
        rot_y(eps_(17)),
        trans(eps_(18) + x_(6), 0.0, 0.0),
        rot_x(eps_(19)),
        rot_y(eps_(20)),
        rot_z(eps_(21)),
    )
    K3 = chain_product(  # Eq. (7.5), after Rot(z, θ3)
        trans_z(eps_(22)),
        rot_x(eps_(23)),
        rot_y(eps_(24)),
        trans(x_(7) + eps_(25), x_(8) + eps_(26), x_(9) + eps_(27)),
        rot_x(x_(10) + eps_(28)),
        rot_y(eps_(29)),
        rot_z(eps_(30)),
    )
    K4 = chain_product(  # Eq. (7.6), after Rot(z, θ4)
        trans(eps_(31), 0.0, x_(11) + eps_(32)),
        rot_x(x_(12) + eps_(33)),
        rot_z(eps_(34)),
    )
    K5 = chain_product(  # Eq. (7.7), after Rot(z, θ5)
        trans_z(eps_(35)),
        rot_x(x_(13) + eps_(36)),
        trans(eps_(37), 0.0, x_(14)),
        rot_z(eps_(38)),
    )
    K6 = trans_z(x_(15) + eps_(39))  # Eq. (7.8), after Rot(z, θ6)
    batch = e.shape[:-1]
    links = np.stack(
        [np.broadcast_to(K, (*batch, 4, 4)) for K in (K1, K2, K3, K4, K5, K6)], axis=-3
    )
    return SerialChain(links=links, prismatic=np.zeros(6, bool), base=K0)


def fk_appendix_b(q: ArrayLike, d3: float, a2: float, a3: float, d4: float) -> Array:
    """Closed-form forward kinematics (B.1)-(B.13), frame 0 at the shoulder.

    Parameters
    ----------
    q : array_like, shape (..., 6)
        Radians.
    d3, a2, a3, d4 : float
        cm. (B.11)-(B.12) carry the shoulder offset as ``d3``; Table 6-2 lists
        it as ``d2``, which is equivalent because joint axes 2 and 3 are parallel.

    Returns
    -------
    T6 : ndarray, shape (..., 4, 4)
        Wrist-centre frame (``d6 = 0``).
    """
    t = np.asarray(q, float)
    S = np.sin(t)
    C = np.cos(t)
    S1, S4, S5, S6 = S[..., 0], S[..., 3], S[..., 4], S[..., 5]
    C1, C2, C4, C5, C6 = C[..., 0], C[..., 1], C[..., 3], C[..., 4], C[..., 5]
    S2 = S[..., 1]
    S23 = np.sin(t[..., 1] + t[..., 2])
    C23 = np.cos(t[..., 1] + t[..., 2])
    T = np.zeros((*t.shape[:-1], 4, 4))
    T[..., 0, 0] = C1 * (C23 * (C4 * C5 * C6 - S4 * S6) - S23 * S5 * C6) - S1 * (
        S4 * C5 * C6 + C4 * S6
    )  # Eq. (B.2)
    T[..., 1, 0] = S1 * (C23 * (C4 * C5 * C6 - S4 * S6) - S23 * S5 * C6) + C1 * (
        S4 * C5 * C6 + C4 * S6
    )  # Eq. (B.3)
    T[..., 2, 0] = -S23 * (C4 * C5 * C6 - S4 * S6) - C23 * S5 * C6  # Eq. (B.4)
    T[..., 0, 1] = C1 * (-C23 * (C4 * C5 * S6 + S4 * C6) + S23 * S5 * S6) - S1 * (
        -S4 * C5 * S6 + C4 * C6
    )  # Eq. (B.5)
    T[..., 1, 1] = S1 * (-C23 * (C4 * C5 * S6 + S4 * C6) + S23 * S5 * S6) + C1 * (
        -S4 * C5 * S6 + C4 * C6
    )  # Eq. (B.6)
    # Eq. (B.7) with the sign of its first term corrected: the print reads
    # -S23(...), which contradicts (B.4) and the D-H chain (docs/errata-found.md).
    T[..., 2, 1] = S23 * (C4 * C5 * S6 + S4 * C6) + C23 * S5 * S6
    T[..., 0, 2] = C1 * (C23 * C4 * S5 + S23 * C5) - S1 * S4 * S5  # Eq. (B.8)
    T[..., 1, 2] = S1 * (C23 * C4 * S5 + S23 * C5) + C1 * S4 * S5  # Eq. (B.9)
    T[..., 2, 2] = -S23 * C4 * S5 + C23 * C5  # Eq. (B.10)
    reach = d4 * S23 + a3 * C23 + a2 * C2
    T[..., 0, 3] = C1 * reach - d3 * S1  # Eq. (B.11)
    T[..., 1, 3] = S1 * reach + d3 * C1  # Eq. (B.12)
    T[..., 2, 3] = -(-d4 * C23 + a3 * S23 + a2 * S2)  # Eq. (B.13)
    T[..., 3, 3] = 1.0
    return T


@dataclass(frozen=True)
class Branch:
    """Configuration branch flags, each +1 or -1.

    ``shoulder``: sign of the wrist centre's reach ``r = d4 S23 + a3 C23 + a2 C2``
    along link 1's x axis (+1 "right": in front of the shoulder, as at q = 0).
    ``elbow``: sign of ``cos(θ3 + atan2(a3, d4))`` (+1 "up", as at q = 0).
    ``wrist``: sign of ``sin θ5`` (+1 "no flip"; θ5 = 0 counts as +1).
    """

    shoulder: int = 1
    elbow: int = 1
    wrist: int = 1

    @property
    def label(self) -> str:
        return "{}-{}-{}".format(
            "right" if self.shoulder > 0 else "left",
            "up" if self.elbow > 0 else "down",
            "noflip" if self.wrist > 0 else "flip",
        )


#: Restarts of a solution outside the limits next to the wrist singularity: θ4 turned by
#: each angle and θ6 by its negative (which keeps θ4 + θ6, the pose at the singularity).
#: There a signature (whose wrist is not exactly spherical) has more solutions on one
#: branch than the solution and its flip: measured on robot3 (580 targets within ~1° of
#: θ5 = 0), 13 converged outside the limits with the in-limit solution 60-300° away in θ4.
#: The real-time solver (:mod:`pipeline.control.puma560_newton`) and
#: :func:`pipeline.control.limits.honour_limits` restart from these turns (here, not in
#: ``control.limits``, so that the compiled kernels' source digest covers them).
WRIST_TURNS = np.array([1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0]) * (np.pi / 4.0)
#: |sin θ5| below which a solution outside the limits gets the :data:`WRIST_TURNS`
#: restarts (5°); farther out the solution and its flip are the branch's only ones.
NEAR_WRIST_SINGULAR = float(np.sin(np.deg2rad(5.0)))
#: The eight branches in the order :func:`inverse_kinematics` returns them.
BRANCHES = tuple(Branch(s, e, w) for s in (1, -1) for e in (1, -1) for w in (1, -1))

_D = np.array(DESIGN_D_CM)
_A = np.array(DESIGN_A_CM)
#: Below this |sin θ5| the wrist is singular: joints 4 and 6 are then aligned and
#: only θ4 + θ6 (or θ6 − θ4) is determined. 1e-10 rad is far below one encoder
#: count (8.7e-5 rad), so treating such poses as singular costs no accuracy.
WRIST_SINGULAR_TOL = 1e-10


def branch_of(q: ArrayLike) -> Array:
    """Branch flags of joint configurations of the design model.

    Parameters
    ----------
    q : array_like, shape (..., 6)
        Radians.

    Returns
    -------
    flags : ndarray of int, shape (..., 3)
        ``(shoulder, elbow, wrist)``, each +1 or -1 (see :class:`Branch`).
    """
    t = np.asarray(q, float)
    a2, a3, d4 = _A[1], _A[2], _D[3]
    s23, c23 = np.sin(t[..., 1] + t[..., 2]), np.cos(t[..., 1] + t[..., 2])
    reach = d4 * s23 + a3 * c23 + a2 * np.cos(t[..., 1])
    elbow = np.cos(t[..., 2] + np.arctan2(a3, d4))
    wrist = np.sin(t[..., 4])
    return np.stack([np.where(v >= 0, 1, -1) for v in (reach, elbow, wrist)], axis=-1)


def flange_and_wrist_centre(
    T: ArrayLike, tool: ArrayLike | None = None, base: ArrayLike | None = None
) -> tuple[Array, Array]:
    """Flange poses in D-H frame 0 (..., 4, 4) and their wrist centres ``p − d6·a`` (..., 3).

    ``T`` are tool poses in the world; ``tool`` is flange to tool, ``base`` world to
    D-H frame 0 (identity when omitted).
    """
    Tw = np.asarray(T, float)
    if tool is not None:
        Tw = Tw @ invert_transform(tool)
    if base is not None:
        Tw = invert_transform(base) @ Tw
    return Tw, Tw[..., :3, 3] - _D[5] * Tw[..., :3, 2]


def inverse_kinematics(
    T: ArrayLike,
    tool: ArrayLike | None = None,
    base: ArrayLike | None = None,
    q4_singular: float = 0.0,
    branches: tuple[Branch, ...] | None = None,
) -> tuple[Array, npt.NDArray[np.bool_]]:
    """All eight closed-form inverse solutions of the Puma 560 design model.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        Desired tool poses in the world frame (cm).
    tool : array_like, shape (4, 4), optional
        Flange to tool transform (identity by default).
    base : array_like, shape (4, 4), optional
        World to D-H frame 0 (identity by default: the design chain's frame 0 is
        already the mounting surface, d1 = 67.4).
    q4_singular : float
        θ4 (radians) chosen when the wrist is singular (|sin θ5| below
        :data:`WRIST_SINGULAR_TOL`); θ6 then takes the whole rotation.
    branches : tuple of Branch, optional
        Only these branches, in this order (default: all of :data:`BRANCHES`).

    Returns
    -------
    q : ndarray, shape (..., 8, 6)
        Radians wrapped to (-π, π], one row per branch in :data:`BRANCHES` order
        (``(..., len(branches), 6)`` when ``branches`` is given).
    reachable : ndarray of bool, shape (..., 8)
        False where the pose is out of that branch's reach (rows are NaN there).
        Joint limits are not applied here.
    """
    Tw, wc = flange_and_wrist_centre(T, tool, base)
    d1, d3, _, d4, _, _ = DESIGN_D_CM  # d3 here is the shoulder offset (d2 = d2+d3)
    a2, a3 = DESIGN_A_CM[1], DESIGN_A_CM[2]
    px, py, pz = wc[..., 0], wc[..., 1], wc[..., 2] - d1
    wanted = BRANCHES if branches is None else branches
    # The branch flags only choose signs: r = ±√rr and the elbow's ±√disc.
    rr = px**2 + py**2 - d3**2
    root_rr = np.sqrt(np.maximum(rr, 0.0))
    Kc = (root_rr**2 + pz**2 - (d4**2 + a3**2 + a2**2)) / (2.0 * a2)  # r2 / (2 a2), (B.22)
    disc = (d4**2 + a3**2) - Kc**2
    valid = (rr >= 0.0) & (disc >= 0.0)
    root_disc = np.sqrt(np.maximum(disc, 0.0))
    phi = math.atan2(a3, d4)
    t1_base = np.arctan2(py, px)
    q = np.empty((*Tw.shape[:-2], len(wanted), 6))
    for k, br in enumerate(wanted):
        r = br.shoulder * root_rr
        t1 = t1_base - np.arctan2(d3, r)  # (px, py) = Rot(θ1)·(r, d3), cf. (B.14)
        t3 = np.arctan2(Kc, br.elbow * root_disc) - phi  # (B.16), ERRATA r2²
        S3, C3 = np.sin(t3), np.cos(t3)
        u = a2 + d4 * S3 + a3 * C3
        v = d4 * C3 - a3 * S3
        t2 = np.arctan2(v * r - u * pz, u * r + v * pz)  # r = u C2 + v S2, pz = v C2 - u S2
        # Wrist: R36 = R03ᵀ R06 = Rot(z,θ4) Rot(y,θ5) Rot(z,θ6) for α4 = -90°, α5 = 90°;
        # the wrist flag is the sign of sin θ5, which multiplies the atan2 arguments.
        R36 = _wrist_rotation(t1, t2 + t3, Tw[..., :3, :3])
        Rw = R36 if br.wrist > 0 else -R36
        s5 = np.hypot(R36[..., 0, 2], R36[..., 1, 2])
        q[..., k, 0], q[..., k, 1], q[..., k, 2] = t1, t2, t3
        q[..., k, 4] = np.arctan2(s5 if br.wrist > 0 else -s5, R36[..., 2, 2])
        q[..., k, 3] = np.arctan2(Rw[..., 1, 2], Rw[..., 0, 2])
        q[..., k, 5] = np.arctan2(Rw[..., 2, 1], -Rw[..., 2, 0])
        singular = s5 < WRIST_SINGULAR_TOL
        if np.count_nonzero(singular):
            # cos θ5 = +1 gives Rot(z, θ4 + θ6); cos θ5 = -1 gives θ6 - θ4 = atan2(r21, -r11).
            t6_sing = np.where(
                R36[..., 2, 2] > 0,
                np.arctan2(R36[..., 1, 0], R36[..., 0, 0]) - q4_singular,
                np.arctan2(R36[..., 1, 0], -R36[..., 0, 0]) + q4_singular,
            )
            q[..., k, 3] = np.where(singular, q4_singular, q[..., k, 3])
            q[..., k, 5] = np.where(singular, t6_sing, q[..., k, 5])
    q = wrap_angle(q)
    if np.count_nonzero(valid) < valid.size:
        q[~valid] = np.nan
    ok = np.empty((*valid.shape, len(wanted)), bool)
    ok[...] = valid[..., None]
    return q, ok


def _wrist_rotation(t1: Array, t23: Array, R06: Array) -> Array:
    """``R03ᵀ R06`` for joints 1-3 at θ1 and θ2 + θ3, shape (..., 3, 3).

    ``R03 = Rot(z,θ1) Rot(x,-90°) Rot(z,θ2+θ3) Rot(x,90°)`` has the columns
    ``(c1 c23, s1 c23, −s23)``, ``(−s1, c1, 0)`` and ``(c1 s23, s1 s23, c23)``;
    row i of the product is column i of R03 combined with the rows of R06.
    """
    c1, s1, c23, s23 = (v[..., None] for v in (np.cos(t1), np.sin(t1), np.cos(t23), np.sin(t23)))
    r0, r1, r2 = R06[..., 0, :], R06[..., 1, :], R06[..., 2, :]
    a = c1 * r0 + s1 * r1
    return np.stack([c23 * a - s23 * r2, c1 * r1 - s1 * r0, s23 * a + c23 * r2], axis=-2)
