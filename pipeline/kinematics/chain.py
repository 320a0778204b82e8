"""Serial kinematic chain in the general form (5.1)-(5.3).

``T(q) = base · Π_i K_i(q_i) · tool`` with ``K_i = Rot(z, q_i − q0_i) · K̄_i`` for a
revolute joint and ``K_i = Trans(0, 0, q_i − q0_i) · K̄_i`` for a prismatic one.
D-H models, S-Models (signatures) and the simulated true robots all reduce to
this one representation, so one forward-kinematics and one Jacobian code path
serve them all.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.kinematics.dh import dh_link
from pipeline.kinematics.transforms import Array, ArrayLike, rot_z, trans_z


@dataclass(frozen=True, eq=False)
class SerialChain:
    """Constant part of a serial chain.

    Attributes
    ----------
    links : ndarray, shape (n, 4, 4) or (..., n, 4, 4)
        ``K̄_i``: the constant transform that follows joint ``i``'s motion. A
        leading batch shape describes many robots at once (Monte-Carlo); it
        broadcasts against the batch shape of ``q``, as do ``base``/``tool``.
    prismatic : ndarray of bool, shape (n,)
        True where joint ``i`` translates along its z axis.
    base : ndarray, shape (4, 4)
        Base (world) to frame of joint 1's axis, ``K_0``.
    tool : ndarray, shape (4, 4)
        Last link frame to tool frame.
    joint_offsets : ndarray, shape (n,)
        ``q0_i`` subtracted from the joint reading (rad or cm).
    """

    links: Array
    prismatic: Array
    base: Array = field(default_factory=lambda: np.eye(4))
    tool: Array = field(default_factory=lambda: np.eye(4))
    joint_offsets: Array | None = None

    def __post_init__(self) -> None:
        links = np.asarray(self.links, float)
        n = links.shape[-3]
        object.__setattr__(self, "links", links)
        object.__setattr__(self, "prismatic", np.asarray(self.prismatic, bool).reshape(n))
        object.__setattr__(self, "base", np.asarray(self.base, float))
        object.__setattr__(self, "tool", np.asarray(self.tool, float))
        off = np.zeros(n) if self.joint_offsets is None else np.asarray(self.joint_offsets, float)
        object.__setattr__(self, "joint_offsets", off.reshape(n))

    @property
    def n_joints(self) -> int:
        return int(self.links.shape[-3])


def chain_from_dh(
    theta: ArrayLike,
    d: ArrayLike,
    a: ArrayLike,
    alpha: ArrayLike,
    prismatic: ArrayLike,
    base: ArrayLike | None = None,
    tool: ArrayLike | None = None,
) -> SerialChain:
    """Serial chain of a D-H model (2.8)-(2.9).

    For a revolute joint ``theta`` is the angle at zero joint reading; for a
    prismatic joint ``d`` is the distance at zero joint reading.

    Parameters
    ----------
    theta, alpha : array_like, shape (n,)
        Radians.
    d, a : array_like, shape (n,)
        cm.
    prismatic : array_like of bool, shape (n,)
    base, tool : array_like, shape (4, 4), optional
    """
    links = dh_link(theta, d, a, alpha)
    return SerialChain(
        links=links,
        prismatic=np.asarray(prismatic, bool),
        base=np.eye(4) if base is None else np.asarray(base, float),
        tool=np.eye(4) if tool is None else np.asarray(tool, float),
    )


def joint_motion(chain: SerialChain, q: ArrayLike) -> Array:
    """Joint motion transforms ``Rot(z, q_i − q0_i)`` or ``Trans(0,0,q_i − q0_i)``.

    Parameters
    ----------
    q : array_like, shape (..., n)

    Returns
    -------
    M : ndarray, shape (..., n, 4, 4)
    """
    qq = np.asarray(q, float) - np.asarray(chain.joint_offsets)
    return np.where(chain.prismatic[:, None, None], trans_z(qq), rot_z(qq))


def link_frames(chain: SerialChain, q: ArrayLike) -> Array:
    """World poses of every frame along the chain.

    Parameters
    ----------
    q : array_like, shape (..., n)
        Joint readings: radians for revolute joints, cm for prismatic ones.

    Returns
    -------
    F : ndarray, shape (..., n + 2, 4, 4)
        ``F[..., i]`` for ``i < n`` is the frame whose z axis is joint ``i+1``'s
        axis (``base · K_1 ⋯ K_i``); ``F[..., n]`` is the last link frame and
        ``F[..., n+1]`` the tool frame.
    """
    M = joint_motion(chain, q)
    K = M @ chain.links  # Eq. (5.2)/(5.3): K_i = Rot(z, q_i)·K̄_i
    batch = K.shape[:-3]
    n = chain.n_joints
    out = np.empty((*batch, n + 2, 4, 4))
    cur = np.broadcast_to(chain.base, (*batch, 4, 4))
    out[..., 0, :, :] = cur
    for i in range(n):
        cur = cur @ K[..., i, :, :]  # Eq. (5.1)
        out[..., i + 1, :, :] = cur
    out[..., n + 1, :, :] = cur @ chain.tool
    return out


def forward_kinematics(chain: SerialChain, q: ArrayLike) -> Array:
    """Tool pose ``T(q) = base · Π K_i(q_i) · tool`` (5.1).

    Parameters
    ----------
    q : array_like, shape (..., n)
        Radians (revolute) / cm (prismatic).

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
    """
    return link_frames(chain, q)[..., -1, :, :]
