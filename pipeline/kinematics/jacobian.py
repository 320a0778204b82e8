"""Geometric manipulator Jacobian of a serial chain, in base coordinates."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.kinematics.transforms import Array, ArrayLike


def geometric_jacobian(chain: SerialChain, q: ArrayLike) -> Array:
    """Geometric Jacobian ``[v; ω] = J(q) q̇`` of the tool frame, base coordinates.

    Column ``i`` is ``[z_i × (p_tool − p_i); z_i]`` for a revolute joint and
    ``[z_i; 0]`` for a prismatic one, where ``z_i``, ``p_i`` are the axis and a
    point of joint ``i`` in the base frame.

    Parameters
    ----------
    q : array_like, shape (..., n)
        Radians (revolute) / cm (prismatic).

    Returns
    -------
    J : ndarray, shape (..., 6, n)
        Rows 0-2: linear velocity (cm per rad or cm per cm); rows 3-5: angular
        velocity (rad per rad; zero for prismatic joints).
    """
    F = link_frames(chain, q)
    n = chain.n_joints
    z = F[..., :n, :3, 2]
    p = F[..., :n, :3, 3]
    p_tool = F[..., n + 1, :3, 3]
    lin_rev = np.cross(z, p_tool[..., None, :] - p)
    pris = chain.prismatic[:, None]
    lin = np.where(pris, z, lin_rev)
    ang = np.where(pris, 0.0, z)
    return np.concatenate([np.swapaxes(lin, -1, -2), np.swapaxes(ang, -1, -2)], axis=-2)
