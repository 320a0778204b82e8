"""Primitive homogeneous transforms (Appendix A) and their algebra.

Every function is batch-first: scalar arguments give a ``(4, 4)`` matrix,
array arguments of shape ``(...)`` give a ``(..., 4, 4)`` stack. Angles are in
radians, lengths in whatever unit the caller uses consistently (cm in armsig).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
ArrayLike = npt.ArrayLike


def _identity_stack(shape: tuple[int, ...]) -> Array:
    out = np.zeros((*shape, 4, 4))
    out[..., 0, 0] = out[..., 1, 1] = out[..., 2, 2] = out[..., 3, 3] = 1.0
    return out


def trans(x: ArrayLike = 0.0, y: ArrayLike = 0.0, z: ArrayLike = 0.0) -> Array:
    """Translation ``Trans(x, y, z)``; the product of the three Appendix A translations.

    Parameters
    ----------
    x, y, z : array_like, shape (...)
        Components of the translation (broadcast against each other).

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
    """
    bx, by, bz = np.broadcast_arrays(
        np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)
    )
    out = _identity_stack(bx.shape)
    out[..., 0, 3] = bx
    out[..., 1, 3] = by
    out[..., 2, 3] = bz
    return out


def trans_x(x: ArrayLike) -> Array:
    """``Trans(x, 0, 0)`` of Appendix A, shape (..., 4, 4)."""
    return trans(x, 0.0, 0.0)


def trans_y(y: ArrayLike) -> Array:
    """``Trans(0, y, 0)`` of Appendix A, shape (..., 4, 4)."""
    return trans(0.0, y, 0.0)


def trans_z(z: ArrayLike) -> Array:
    """``Trans(0, 0, z)`` of Appendix A, shape (..., 4, 4)."""
    return trans(0.0, 0.0, z)


def _rot(theta: ArrayLike, i: int, j: int) -> Array:
    """Rotation in the (i, j) coordinate plane: R[i,i]=R[j,j]=c, R[i,j]=-s, R[j,i]=s."""
    t = np.asarray(theta, float)
    c, s = np.cos(t), np.sin(t)
    out = _identity_stack(t.shape)
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rot_x(theta: ArrayLike) -> Array:
    """``Rot(x, θ)`` of Appendix A; ``theta`` in radians, shape (...) -> (..., 4, 4)."""
    return _rot(theta, 1, 2)


def rot_y(theta: ArrayLike) -> Array:
    """``Rot(y, θ)`` of Appendix A; ``theta`` in radians, shape (...) -> (..., 4, 4)."""
    return _rot(theta, 2, 0)


def rot_z(theta: ArrayLike) -> Array:
    """``Rot(z, θ)`` of Appendix A; ``theta`` in radians, shape (...) -> (..., 4, 4)."""
    return _rot(theta, 0, 1)


def invert_transform(A2B: ArrayLike) -> Array:
    """Closed-form inverse of a homogeneous transform: ``[Rᵀ, -Rᵀp; 0, 1]``.

    Parameters
    ----------
    A2B : array_like, shape (..., 4, 4)
        Rigid transforms (rotation block orthonormal).

    Returns
    -------
    B2A : ndarray, shape (..., 4, 4)
    """
    T = np.asarray(A2B, float)
    R_t = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = R_t
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", R_t, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def chain_product(*factors: ArrayLike) -> Array:
    """Left-to-right product of broadcastable ``(..., 4, 4)`` stacks."""
    out = np.asarray(factors[0], float)
    for f in factors[1:]:
        out = out @ np.asarray(f, float)
    return out


def pose_error(T_desired: ArrayLike, T_actual: ArrayLike) -> tuple[Array, Array]:
    """Position and orientation error between two transform stacks.

    Parameters
    ----------
    T_desired, T_actual : array_like, shape (..., 4, 4)

    Returns
    -------
    dp : ndarray, shape (...)
        Euclidean distance between the origins (length unit of the inputs).
    dtheta : ndarray, shape (...)
        Angle of the relative rotation ``R_dᵀ R_a`` in radians, in [0, π].
    """
    Td = np.asarray(T_desired, float)
    Ta = np.asarray(T_actual, float)
    dp = np.linalg.norm(Td[..., :3, 3] - Ta[..., :3, 3], axis=-1)
    R = np.swapaxes(Td[..., :3, :3], -1, -2) @ Ta[..., :3, :3]
    # Use the axis-angle identity with both sin and cos for accuracy near 0 and π.
    cos_t = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    skew = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    sin_t = np.linalg.norm(skew, axis=-1) / 2.0
    return dp, np.arctan2(sin_t, cos_t)


#: Components (y, z, x, y) of a 3-vector: slices [0:3] and [1:4] of them are the two
#: cyclic shifts a cross product multiplies.
_CYCLE = np.array([1, 2, 0, 1])

#: Up to this many elements per operand, :func:`cross3` multiplies the two cyclic
#: shifts (3 operations after 2 gathers); above it, component by component
#: (9 operations on contiguous slices, ~3x faster for 10⁶ elements).
_CROSS_SHIFT_MAX = 3000


def cross3(a: Array, b: Array, axis: int = -1) -> Array:
    """Cross product of 3-vectors stored along ``axis`` (a negative axis).

    Same as ``np.cross(a, b, axis=axis)`` (the same products and differences),
    without its per-call axis bookkeeping (which dominates for small stacks).
    """
    tail: tuple[slice, ...] = (slice(None),) * (-axis - 1)
    if a.size <= _CROSS_SHIFT_MAX and b.size <= _CROSS_SHIFT_MAX:
        lo: tuple[Any, ...] = (Ellipsis, slice(0, 3), *tail)
        hi: tuple[Any, ...] = (Ellipsis, slice(1, 4), *tail)
        aa, bb = a.take(_CYCLE, axis=axis), b.take(_CYCLE, axis=axis)
        out: Array = aa[lo] * bb[hi] - aa[hi] * bb[lo]  # (a_y b_z − a_z b_y, ...)
        return out

    def c(i: int, arr: Array) -> Array:
        index: tuple[Any, ...] = (Ellipsis, i, *tail)
        comp: Array = arr[index]
        return comp

    return np.stack(
        [
            c(1, a) * c(2, b) - c(2, a) * c(1, b),
            c(2, a) * c(0, b) - c(0, a) * c(2, b),
            c(0, a) * c(1, b) - c(1, a) * c(0, b),
        ],
        axis=axis,
    )


def angle_between(u: ArrayLike, v: ArrayLike) -> Array:
    """Angle (rad, [0, π]) between vectors (..., 3); atan2 keeps it exact near 90°."""
    a = np.asarray(u, float)
    b = np.asarray(v, float)
    out: Array = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))
    return out


#: Flat indices into a 3x3 matrix: R21, R02, R10, R12, R20, R01, R00, R11, R22.
_SKEW_TRACE = np.array([7, 2, 3, 5, 6, 1, 0, 4, 8])
_ONES3 = np.ones(3)


def differential_motion(T_from: ArrayLike, T_to: ArrayLike) -> Array:
    """Small-motion vector taking ``T_from`` to ``T_to``, in base coordinates.

    The rotation part is the exact axis-angle vector of ``R_to R_fromᵀ`` (so it
    stays meaningful for large errors), the translation part the difference of
    origins. This is the differential δ of Section 5.2 expressed in the base frame.

    Parameters
    ----------
    T_from, T_to : array_like, shape (..., 4, 4)

    Returns
    -------
    delta : ndarray, shape (..., 6)
        ``[dx, dy, dz, δx, δy, δz]``; translation in length units, rotation in radians.
    """
    Tf = np.asarray(T_from, float)
    Tt = np.asarray(T_to, float)
    R = Tt[..., :3, :3] @ Tf[..., :3, :3].swapaxes(-1, -2)  # R_to R_fromᵀ
    # One gather: R21, R02, R10 | R12, R20, R01 (the skew part) | R00, R11, R22.
    g = R.reshape(*R.shape[:-2], 9).take(_SKEW_TRACE, axis=-1)
    skew = g[..., :3] - g[..., 3:6]  # 2 sin(θ) · axis
    # Sums over 3 components as products with ones: numpy reduces short axes slowly.
    two_sin = np.sqrt((skew * skew) @ _ONES3)
    angle = np.arctan2(two_sin, g[..., 6:] @ _ONES3 - 1.0)  # tr R − 1 = 2 cos(θ)
    # θ / (2 sin θ) = 1/2 + θ²/12 + …: for sin θ below 1e-12 (round-off of R) the
    # limit 1/2 is exact to double precision, and the division is guarded.
    scale = np.divide(angle, two_sin, out=np.full_like(angle, 0.5), where=two_sin > 2e-12)
    out = np.empty((*R.shape[:-2], 6))
    np.subtract(Tt[..., :3, 3], Tf[..., :3, 3], out=out[..., :3])
    np.multiply(skew, scale[..., None], out=out[..., 3:])
    return out


def transform_from_xyz_rpy(xyz: ArrayLike, rpy: ArrayLike) -> Array:
    """Pose ``Trans(x, y, z) · Rot(z, rz) · Rot(y, ry) · Rot(x, rx)``.

    Parameters
    ----------
    xyz : array_like, shape (..., 3)
        Position (cm).
    rpy : array_like, shape (..., 3)
        ``(rx, ry, rz)`` fixed-axis roll, pitch, yaw in radians.

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
    """
    p = np.asarray(xyz, float)
    r = np.asarray(rpy, float)
    return (
        trans(p[..., 0], p[..., 1], p[..., 2])
        @ rot_z(r[..., 2])
        @ rot_y(r[..., 1])
        @ rot_x(r[..., 0])
    )


def xyz_rpy_from_transform(T: ArrayLike) -> tuple[Array, Array]:
    """Inverse of :func:`transform_from_xyz_rpy`.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)

    Returns
    -------
    xyz : ndarray, shape (..., 3)
    rpy : ndarray, shape (..., 3)
        ``(rx, ry, rz)`` radians with ``ry`` in [-π/2, π/2]; at ``|ry| = π/2``
        the split between ``rx`` and ``rz`` is arbitrary and ``rx = 0`` is returned.
    """
    M = np.asarray(T, float)
    R = M[..., :3, :3]
    ry = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 0, 0], R[..., 1, 0]))
    # cos(ry) below 1e-12 means gimbal lock: the rx/rz split is undetermined.
    locked = np.hypot(R[..., 0, 0], R[..., 1, 0]) < 1e-12
    rz = np.where(
        locked, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), np.arctan2(R[..., 1, 0], R[..., 0, 0])
    )
    # rx from Rot(z, -rz) · R = Rot(y, ry) · Rot(x, rx), whose row 1 is [0, cos rx, -sin rx]:
    # it absorbs the error of rz, so near gimbal lock the pose is still rebuilt to round-off
    # (atan2(R21, R22) alone erred by up to 1e-5 at cos(ry) = 1e-11).
    cz, sz = np.cos(rz), np.sin(rz)
    rx = np.where(
        locked,
        0.0,
        np.arctan2(sz * R[..., 0, 2] - cz * R[..., 1, 2], cz * R[..., 1, 1] - sz * R[..., 0, 1]),
    )
    return M[..., :3, 3].copy(), np.stack([rx, ry, rz], axis=-1)


def wrap_angle(theta: ArrayLike) -> Array:
    """Wrap radians to (-π, π], any shape."""
    t = np.asarray(theta, float)
    out: Array = np.pi - np.mod(np.pi - t, 2.0 * np.pi)
    return out
