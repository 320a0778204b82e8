"""Geometric manipulator Jacobian of a serial chain, in base coordinates."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.chain import SerialChain, frames_soa, link_frames
from pipeline.kinematics.transforms import Array, ArrayLike, cross3


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
    return pose_and_jacobian(chain, q)[1]


def pose_and_jacobian(chain: SerialChain, q: ArrayLike) -> tuple[Array, Array]:
    """Tool pose and geometric Jacobian from one pass along the chain.

    Parameters
    ----------
    q : array_like, shape (..., n)
        Radians (revolute) / cm (prismatic).

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
        Tool pose ``T(q)`` (5.1), cm.
    J : ndarray, shape (..., 6, n)
        As :func:`geometric_jacobian`.
    """
    qq = np.asarray(q, float)
    n = chain.n_joints
    pris = chain.prismatic[:, None]
    if chain.links.ndim == 3 and chain.base.ndim == 2 and chain.tool.ndim == 2:
        F, tool = frames_soa(chain, qq.reshape(-1, n), columns=(2, 3))
        z, p = F[:n, 0], F[:n, 1]  # (n, 3, m): joint axes and origins
        lin_rev = cross3(z, tool[3][None] - p, axis=-2)
        J_soa = np.concatenate(
            [np.where(pris[..., None], z, lin_rev), np.where(pris[..., None], 0.0, z)], 1
        )
        m = tool.shape[-1]
        T = np.zeros((m, 4, 4))
        T[:, :3, :] = np.moveaxis(tool, (-1, 0), (0, -1))
        T[:, 3, 3] = 1.0
        J = np.ascontiguousarray(np.moveaxis(J_soa, (-1, 0), (0, -1)))
        return T.reshape(*qq.shape[:-1], 4, 4), J.reshape(*qq.shape[:-1], 6, n)
    Fr = link_frames(chain, qq)
    z = Fr[..., :n, :3, 2]
    p = Fr[..., :n, :3, 3]
    p_tool = Fr[..., n + 1, :3, 3]
    lin_rev = cross3(z, p_tool[..., None, :] - p)
    lin = np.where(pris, z, lin_rev)
    ang = np.where(pris, 0.0, z)
    J = np.concatenate([np.swapaxes(lin, -1, -2), np.swapaxes(ang, -1, -2)], axis=-2)
    return Fr[..., n + 1, :, :], J
