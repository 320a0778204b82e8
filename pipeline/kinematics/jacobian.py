"""Geometric manipulator Jacobian of a serial chain, in base coordinates."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.chain import (
    SerialChain,
    frames_soa,
    is_single_robot,
    link_frames,
    soa_blocks,
)
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
    if is_single_robot(chain):
        return _pose_and_jacobian_soa(chain, qq)
    Fr = link_frames(chain, qq)
    z = Fr[..., :n, :3, 2]
    lin = cross3(z, Fr[..., n + 1, None, :3, 3] - Fr[..., :n, :3, 3])
    if chain.motion_basis[2]:  # prismatic columns are [z_i; 0]
        pris = chain.prismatic[:, None]
        lin, z = np.where(pris, z, lin), np.where(pris, 0.0, z)
    J = np.concatenate([lin, z], axis=-1)  # (..., n, 6)
    return Fr[..., n + 1, :, :], J.swapaxes(-1, -2)


def _pose_and_jacobian_soa(chain: SerialChain, q: Array) -> tuple[Array, Array]:
    """:func:`pose_and_jacobian` from the column-major frames of :func:`frames_soa`."""
    n = chain.n_joints
    q2 = q.reshape(-1, n)
    m = q2.shape[0]
    blocks = soa_blocks(m)
    if len(blocks) == 1:
        T, J = _pose_and_jacobian_block(chain, q2)
    else:
        T, J = np.empty((m, 4, 4)), np.empty((m, 6, n))
        for block in blocks:
            T[block], J[block] = _pose_and_jacobian_block(chain, q2[block])
    batch = q.shape[:-1]
    return T.reshape(*batch, 4, 4), J.reshape(*batch, 6, n)


def _pose_and_jacobian_block(chain: SerialChain, q: Array) -> tuple[Array, Array]:
    """Poses (k, 4, 4) and Jacobians (k, 6, n) of one block of poses ``q`` (k, n)."""
    n = chain.n_joints
    F, tool = frames_soa(chain, q, columns=(2, 3))
    z, p = F[:n, 0].swapaxes(0, 1), F[:n, 1].swapaxes(0, 1)  # (3, n, k): axes, origins
    J = np.empty((6, n, q.shape[0]))
    J[:3] = cross3(z, tool[3][:, None] - p, axis=-3)
    J[3:] = z
    if chain.motion_basis[2]:  # prismatic columns are [z_i; 0]
        J[:3, chain.prismatic] = z[:, chain.prismatic]
        J[3:, chain.prismatic] = 0.0
    T = np.empty((q.shape[0], 4, 4))
    T[:, :3, :] = tool.transpose(2, 1, 0)
    T[:, 3, :] = (0.0, 0.0, 0.0, 1.0)
    # One transposing copy to the batch-first layout (a strided view would slow
    # down every later gather and solve about as much as this copy costs).
    return T, J.reshape(6 * n, -1).T.reshape(-1, 6, n)
