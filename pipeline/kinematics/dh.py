"""Denavit-Hartenberg link matrix (Section 2.2.1)."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.transforms import Array, ArrayLike


def dh_link(theta: ArrayLike, d: ArrayLike, a: ArrayLike, alpha: ArrayLike) -> Array:
    """D-H link matrix ``A_i = Rot(z,θ) Trans(0,0,d) Trans(a,0,0) Rot(x,α)``.

    The same matrix serves revolute joints (θ variable) and prismatic joints
    (d variable); the caller decides which argument carries the joint value.

    Parameters
    ----------
    theta, alpha : array_like, shape (...)
        Joint angle and link twist, radians.
    d, a : array_like, shape (...)
        Joint distance and link length (cm).

    Returns
    -------
    A : ndarray, shape (..., 4, 4)
    """
    th, dd, aa, al = np.broadcast_arrays(*(np.asarray(v, float) for v in (theta, d, a, alpha)))
    ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
    out = np.zeros((*th.shape, 4, 4))
    out[..., 0, 0] = ct  # Eq. (2.10)
    out[..., 0, 1] = -st * ca
    out[..., 0, 2] = st * sa
    out[..., 0, 3] = aa * ct
    out[..., 1, 0] = st
    out[..., 1, 1] = ct * ca
    out[..., 1, 2] = -ct * sa
    out[..., 1, 3] = aa * st
    out[..., 2, 1] = sa
    out[..., 2, 2] = ca
    out[..., 2, 3] = dd
    out[..., 3, 3] = 1.0
    return out
