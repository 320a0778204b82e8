"""S-Model link matrix and its parameters (Chapter 3).

An S-Model link is six numbers ``(β, d̄, ā, ᾱ, γ, b)`` (3.2). This module builds
the matrix from them, recovers them from any rigid transform by backward
multiplication (3.17)-(3.33) with the corrections of ERRATA.md, and extracts
D-H parameters (3.12)-(3.15).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.kinematics.transforms import Array, ArrayLike

#: Below this |sin ᾱ| (or sqrt(a_x² + a_y²)) two joint axes count as parallel.
#: 1e-12 is ~1e4 ulps of 1.0: it catches axes parallel up to rounding of
#: products of rotation matrices, while an axis tilted by 1e-9 rad (|b| ~ 1e9 cm
#: at 1 cm offset) is still treated as skew, so nearly parallel axes are exact.
PARALLEL_TOL = 1e-12


@dataclass(frozen=True)
class SModelParams:
    """Six S-Model parameters of one or many links (3.2).

    Attributes
    ----------
    beta, alpha_bar, gamma : ndarray, shape (...)
        Radians.
    d_bar, a_bar, b : ndarray, shape (...)
        Length unit of the source transform (cm).
    """

    beta: Array
    d_bar: Array
    a_bar: Array
    alpha_bar: Array
    gamma: Array
    b: Array


def matrix_from_smodel(
    beta: ArrayLike,
    d_bar: ArrayLike,
    a_bar: ArrayLike,
    alpha_bar: ArrayLike,
    gamma: ArrayLike,
    b: ArrayLike,
) -> Array:
    """S-Model link matrix (3.2).

    ``B = Rot(z,β) Trans(0,0,d̄) Trans(ā,0,0) Rot(x,ᾱ) Rot(z,γ) Trans(0,0,b)``.

    Parameters
    ----------
    beta, alpha_bar, gamma : array_like, shape (...)
        Radians.
    d_bar, a_bar, b : array_like, shape (...)
        Lengths (cm).

    Returns
    -------
    B : ndarray, shape (..., 4, 4)
    """
    be, dd, aa, al, ga, bb = np.broadcast_arrays(
        *(np.asarray(v, float) for v in (beta, d_bar, a_bar, alpha_bar, gamma, b))
    )
    cb, sb, ca, sa, cg, sg = np.cos(be), np.sin(be), np.cos(al), np.sin(al), np.cos(ga), np.sin(ga)
    out = np.zeros((*be.shape, 4, 4))
    out[..., 0, 0] = cb * cg - sb * ca * sg  # Eq. (3.4)
    out[..., 1, 0] = sb * cg + cb * ca * sg  # Eq. (3.5)
    out[..., 0, 1] = -cb * sg - sb * ca * cg  # Eq. (3.6)
    out[..., 1, 1] = -sb * sg + cb * ca * cg  # Eq. (3.7)
    out[..., 2, 0] = sa * sg  # Eq. (3.3)
    out[..., 2, 1] = sa * cg
    out[..., 0, 2] = sb * sa
    out[..., 1, 2] = -cb * sa
    out[..., 2, 2] = ca
    out[..., 0, 3] = bb * sb * sa + aa * cb
    out[..., 1, 3] = -bb * cb * sa + aa * sb
    out[..., 2, 3] = bb * ca + dd
    out[..., 3, 3] = 1.0
    return out


def smodel_from_matrix(B: ArrayLike) -> SModelParams:
    """Six S-Model parameters of rigid transforms, by backward multiplication.

    Rules (ERRATA.md): ``β = atan2(−a_x, a_y)`` (3.21); for parallel axes ``β``
    points along the common normal, folded to (-π/2, π/2], which is the ``β = 0``
    of (3.23) whenever (3.23) can rebuild ``B``; ``atan2`` for (3.26) and (3.29); the sign of ``b``
    follows from (3.31), and ``b = 0`` when ``sin ᾱ = 0`` (3.32).

    Parameters
    ----------
    B : array_like, shape (..., 4, 4)
        Rigid transforms from frame ``S_{i-1}`` to ``S_i``.

    Returns
    -------
    SModelParams
        Arrays of shape (...). ``matrix_from_smodel(**vars(p))`` reproduces ``B``.
    """
    T = np.asarray(B, float)
    nx, ny = T[..., 0, 0], T[..., 1, 0]
    ox, oy = T[..., 0, 1], T[..., 1, 1]
    ax, ay, az = T[..., 0, 2], T[..., 1, 2], T[..., 2, 2]
    px, py, pz = T[..., 0, 3], T[..., 1, 3], T[..., 2, 3]
    parallel = np.hypot(ax, ay) < PARALLEL_TOL
    # Parallel axes: (3.23) sets β = 0, which rebuilds B only when p_y = 0. We take β
    # along the common normal, folded into (-π/2, π/2] so that it *is* 0 whenever
    # p_y = 0 (then (3.23) holds) and B is rebuilt for any offset (docs/errata-found.md).
    fold = np.where(px < 0.0, -1.0, 1.0)
    beta_parallel = np.where(np.hypot(px, py) > 0.0, np.arctan2(py * fold, px * fold), 0.0)
    beta = np.where(parallel, beta_parallel, np.arctan2(-ax, ay))  # Eq. (3.21), (3.23)
    cb, sb = np.cos(beta), np.sin(beta)
    alpha = np.arctan2(ax * sb - ay * cb, az)  # Eq. (3.26), atan2 per ERRATA
    gamma = np.arctan2(-ox * cb - oy * sb, nx * cb + ny * sb)  # Eq. (3.29), atan2 per ERRATA
    a_bar = px * cb + py * sb  # Eq. (3.30)
    sa = np.sin(alpha)
    safe = np.abs(sa) >= PARALLEL_TOL
    b = np.where(
        safe, (px * sb - py * cb) / np.where(safe, sa, 1.0), 0.0
    )  # Eq. (3.32), ERRATA sign
    d_bar = pz - b * np.cos(alpha)  # Eq. (3.33)
    return SModelParams(
        beta=np.asarray(beta),
        d_bar=np.asarray(d_bar),
        a_bar=np.asarray(a_bar),
        alpha_bar=np.asarray(alpha),
        gamma=np.asarray(gamma),
        b=np.asarray(b),
    )


@dataclass(frozen=True)
class DHParams:
    """D-H parameters of a chain of links, each an array of shape (n,).

    ``theta`` and ``alpha`` in radians, ``d`` and ``a`` in cm. For a prismatic
    joint obtained through (3.12)-(3.15) these are the *modified* D-H parameters.
    """

    theta: Array
    d: Array
    a: Array
    alpha: Array


def dh_from_smodel(links: SModelParams) -> DHParams:
    """D-H parameters of a chain from its S-Model parameters, (3.12)-(3.15).

    Parameters
    ----------
    links : SModelParams
        Arrays of shape (..., n): link ``i`` of the chain in the last axis.
        ``γ_0 = b_0 = 0`` (frame S_0 is taken as the D-H frame T_0).

    Returns
    -------
    DHParams
        Arrays of shape (..., n).
    """
    gamma_prev = np.concatenate(
        [np.zeros_like(links.gamma[..., :1]), links.gamma[..., :-1]], axis=-1
    )
    b_prev = np.concatenate([np.zeros_like(links.b[..., :1]), links.b[..., :-1]], axis=-1)
    return DHParams(
        theta=links.beta + gamma_prev,  # Eq. (3.12)
        d=links.d_bar + b_prev,  # Eq. (3.13)
        a=np.asarray(links.a_bar),  # Eq. (3.14)
        alpha=np.asarray(links.alpha_bar),  # Eq. (3.15)
    )
