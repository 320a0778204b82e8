"""True D-H parameters of robots with prismatic joints (Section 4.3.5, (4.61)-(4.73)).

Applying (3.12)-(3.15) to a prismatic joint ``i`` gives the *modified* D-H
parameters, with ``a_i ≠ 0``, because the S-Model frame ``S_{i−1}`` of a
prismatic joint sits on an arbitrary line parallel to the direction of travel
(Figure 4-6). Any translation of ``S_{i−1}`` and any rotation about its z axis
commutes with the joint's motion ``Trans(0, 0, q_i)``, so relocating the frame
leaves the kinematics unchanged. Section 4.3.5 relocates it so that

- the line of translation meets joint ``i+1``'s axis: ``ā_i = 0``, hence
  ``a_i = 0`` (3.14) by construction;
- the new frame is the D-H frame ``T_{i−1}``: ``γ_{i−1} = b_{i−1} = 0``;
- the line meets axis ``i+1`` where ``d_{i+1} = 0``: ``b_i = −d̄_{i+1}``.

``ᾱ_i`` and ``γ_i`` of the new ``B_i`` come from the joint ``i`` and ``i+1`` axes
(4.61)/(4.62) (ERRATA.md), and the six parameters of link ``i−1`` plus ``β_i``
and ``d̄_i`` from the backward multiplication (4.65)-(4.70) of the left-hand side
of (4.64).

Cases the thesis only names (end of Section 4.3.5), with the rules used here:

- consecutive prismatic joints: joints are relocated from the tip to the base,
  and the line of joint ``i`` passes through the (already relocated) origin of
  ``S_i``: the frame origins coincide, ``b_i = 0``;
- last joint prismatic: its line passes through the origin of ``S_n``
  (``b_n = 0``); for an identified chain ``S̄_n = S̄_{n−1}`` already does;
- first joint prismatic: there is no ``B_0`` (4.71), so the base frame ``S_0``
  slides sideways onto the relocated line, keeping its orientation.
"""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.signature import PseudoDH, pseudo_dh_from_smodel
from pipeline.kinematics.smodel import (
    PARALLEL_TOL,
    SModelParams,
    matrix_from_smodel,
    smodel_from_matrix,
)
from pipeline.kinematics.transforms import Array, rot_x, rot_z, trans, trans_z, wrap_angle

_FIELDS = ("beta", "d_bar", "a_bar", "alpha_bar", "gamma", "b")


def _link(p: dict[str, Array], k: int) -> Array:
    """Matrix (3.2) of link ``k`` (0-based) of the parameter arrays ``p`` (..., n)."""
    return matrix_from_smodel(*(p[f][..., k] for f in _FIELDS))


def _axes_angles(B: Array) -> tuple[Array, Array]:
    """``ᾱ_i`` (4.61) and ``γ_i`` (4.62) of links ``B`` (..., 4, 4), radians.

    ``ᾱ_i`` is the angle between the joint ``i`` axis ``[0, 0, 1]`` and the joint
    ``i+1`` axis ``a``; ``γ_i`` the angle about ``a`` from the new X axis
    ``[−a_y, a_x, 0] / |·|`` (their common normal) to the X axis ``n`` of ``S_i``.
    Parallel axes have no common normal: the new X axis is ``n`` itself, ``γ_i = 0``.
    """
    n, a = B[..., :3, 0], B[..., :3, 2]
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    s = np.hypot(ax, ay)
    alpha = np.arctan2(s, az)  # Eq. (4.61), ERRATA: atan2(sqrt(a_x² + a_y²), a_z)
    parallel = s < PARALLEL_TOL
    x_new = np.stack([-ay, ax, np.zeros_like(ax)], axis=-1) / np.where(parallel, 1.0, s)[..., None]
    cos_g = np.sum(x_new * n, axis=-1)
    sin_g = np.sum(np.cross(x_new, n) * a, axis=-1)
    gamma = np.where(parallel, 0.0, np.arctan2(sin_g, cos_g))  # Eq. (4.62), ERRATA: dot/cross
    return alpha, gamma


def relocate_prismatic(
    sm: SModelParams, prismatic: np.ndarray, base: Array
) -> tuple[SModelParams, Array]:
    """S-Model parameters and base after relocating every prismatic joint's frame.

    Parameters
    ----------
    sm : SModelParams
        Links of the chain, arrays of shape (..., n).
    prismatic : ndarray of bool, shape (n,)
    base : ndarray, shape (..., 4, 4)
        World to ``S_0``.

    Returns
    -------
    SModelParams, ndarray (..., 4, 4)
        New links (``ā_i = 0`` exactly on prismatic joints) and the base, which
        changes only when joint 1 is prismatic. ``base · Π M_i · B_i`` is unchanged.
    """
    p = {f: np.array(getattr(sm, f), float) for f in _FIELDS}  # copies, (..., n)
    n = p["beta"].shape[-1]
    base = np.array(np.broadcast_to(base, (*p["beta"].shape[:-1], 4, 4)))
    for k in reversed(np.flatnonzero(prismatic)):  # joint i = k + 1, tip to base
        B_i = _link(p, k)
        alpha_i, gamma_i = _axes_angles(B_i)
        if k + 1 < n and not prismatic[k + 1]:
            b_i = -p["d_bar"][..., k + 1]  # b_i = −d̄_{i+1}: the line meets axis i+1 at d_{i+1} = 0
        else:
            b_i = np.zeros_like(alpha_i)  # next joint prismatic, or none: origins coincide
        if k + 1 < n and prismatic[k + 1]:
            # S_i is already the D-H frame T_i: take the twin of (4.61)/(4.62) (ᾱ → −ᾱ,
            # γ → γ + π; ERRATA: either X sense is valid) that keeps S_i's X, γ_i = 0.
            twin = np.abs(gamma_i) > np.pi / 2
            alpha_i = np.where(twin, -alpha_i, alpha_i)
            gamma_i = np.where(twin, wrap_angle(gamma_i + np.pi), gamma_i)
        # Eq. (4.64): everything right of B_{i−1} on its left-hand side.
        tail = B_i @ trans_z(-b_i) @ rot_z(-gamma_i) @ rot_x(-alpha_i)
        if k == 0:
            # No B_0 (4.71): the relocated S_0 keeps its orientation and its z
            # origin, and moves sideways onto the line through the tail's origin.
            base = base @ trans(tail[..., 0, 3], tail[..., 1, 3], 0.0)
            # The tail is now Rot(z, β_1) Trans(0, 0, d̄_1).
            beta_i = np.arctan2(tail[..., 1, 0], tail[..., 0, 0])
            d_bar_i = tail[..., 2, 3]
        else:
            q = smodel_from_matrix(_link(p, k - 1) @ tail)  # Eq. (4.64)
            p["beta"][..., k - 1] = q.beta  # Eq. (4.65)
            p["alpha_bar"][..., k - 1] = q.alpha_bar  # Eq. (4.66)
            p["a_bar"][..., k - 1] = q.a_bar  # Eq. (4.68)
            p["d_bar"][..., k - 1] = q.d_bar  # Eq. (4.70)
            p["gamma"][..., k - 1] = 0.0  # γ_{i−1} = 0: S_{i−1} is now T_{i−1}
            p["b"][..., k - 1] = 0.0  # b_{i−1} = 0
            beta_i = q.gamma  # Eq. (4.67)
            d_bar_i = q.b  # Eq. (4.69), ERRATA sign of b
        p["beta"][..., k] = beta_i
        p["d_bar"][..., k] = d_bar_i
        p["a_bar"][..., k] = 0.0  # ā_i = 0 by construction, so a_i = 0 (3.14)
        p["alpha_bar"][..., k] = alpha_i
        p["gamma"][..., k] = gamma_i
        p["b"][..., k] = b_i
    return SModelParams(**p), base


def true_dh_from_chain(chain: SerialChain) -> PseudoDH:
    """True pseudo D-H model (4.71) of a chain: ``a_i = 0`` on every prismatic joint.

    Encoder offsets follow (4.59)/(4.72)/(4.73): for a prismatic joint
    ``d_i = q̄_i + (d_i^s − q̄_i^s)`` with ``d_i^s = d̄_i`` of the relocated link.
    Without prismatic joints this equals
    :func:`pipeline.kinematics.signature.pseudo_dh_from_chain`. Batched:
    ``chain.links`` may have shape (..., n, 4, 4).
    """
    sm, base = relocate_prismatic(smodel_from_matrix(chain.links), chain.prismatic, chain.base)
    qs = np.asarray(chain.joint_offsets, float)
    return pseudo_dh_from_smodel(sm, chain.prismatic, qs, base, chain.tool)
