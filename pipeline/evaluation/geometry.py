"""Small geometry of the grid-touching tasks: the taught workspace frame (Section 6.5),
rotation vectors, line lengths, normal deviations and angles between grid lines.

Batch first: points (..., 3), rotations (..., 3, 3); lengths in cm, angles in radians.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import KinematicsError
from pipeline.kinematics.transforms import Array, ArrayLike, differential_motion


def workspace_from_points(p1: ArrayLike, p2: ArrayLike, p3: ArrayLike) -> Array:
    """Workspace frame taught from three end-effector positions (Section 6.5).

    Origin at point 1, X along 1 -> 2, Z normal to the plane of 1, 2, 3 (on the
    side of ``(p2 - p1) × (p3 - p1)``), Y completing the right-handed set.

    Parameters
    ----------
    p1, p2, p3 : array_like, shape (..., 3)
        cm, in any common frame.

    Returns
    -------
    W : ndarray, shape (..., 4, 4)
        The workspace frame in that common frame.
    """
    a, b, c = (np.asarray(p, float) for p in (p1, p2, p3))
    x = b - a
    z = np.cross(x, c - a)
    nx, nz = np.linalg.norm(x, axis=-1), np.linalg.norm(z, axis=-1)
    # 1e-9 cm: far below any taught spacing (cm) and far above round-off.
    if np.any(nx < 1e-9) or np.any(nz < 1e-9 * np.maximum(nx, 1.0)):
        raise KinematicsError(
            "teach points do not span a plane",
            expected="three distinct, non-collinear end-effector positions",
            fix="re-teach the workspace frame on three well separated fixture points",
        )
    x = x / nx[..., None]
    z = z / nz[..., None]
    W = np.zeros((*a.shape[:-1], 4, 4))
    W[..., :3, 0] = x
    W[..., :3, 1] = np.cross(z, x)
    W[..., :3, 2] = z
    W[..., :3, 3] = a
    W[..., 3, 3] = 1.0
    return W


def rotation_vector(R_from: ArrayLike, R_to: ArrayLike) -> Array:
    """Axis-angle vector (rad) of ``R_to R_fromᵀ`` in the common frame, shape (..., 3)."""
    Rf = np.asarray(R_from, float)
    Rt = np.asarray(R_to, float)
    Tf = np.zeros((*Rf.shape[:-2], 4, 4))
    Tt = np.zeros((*Rt.shape[:-2], 4, 4))
    Tf[..., :3, :3] = Rf
    Tt[..., :3, :3] = Rt
    return differential_motion(Tf, Tt)[..., 3:]


def rotation_from_vector(w: ArrayLike) -> Array:
    """Rotation matrices (..., 3, 3) of axis-angle vectors (..., 3) in rad (Rodrigues)."""
    v = np.asarray(w, float)
    angle = np.linalg.norm(v, axis=-1)
    # Series below 1e-8 rad: sin(t)/t and (1 - cos t)/t² are exact to round-off there.
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    s = np.where(small, 1.0 - angle**2 / 6.0, np.sin(safe) / safe)
    c = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    K = np.zeros((*v.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2] = -v[..., 2], v[..., 1]
    K[..., 1, 0], K[..., 1, 2] = v[..., 2], -v[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -v[..., 1], v[..., 0]
    out: Array = np.eye(3) + s[..., None, None] * K + c[..., None, None] * (K @ K)
    return out


def distance(a: ArrayLike, b: ArrayLike) -> Array:
    """Euclidean distance between points (..., d), d = 2 or 3."""
    return np.linalg.norm(np.asarray(b, float) - np.asarray(a, float), axis=-1)


def normal_deviation(points: ArrayLike, start: ArrayLike, end: ArrayLike) -> Array:
    """Distance of ``points`` (..., k, d) from the line through ``start``/``end`` (..., d).

    ``d`` is 2 (marks on the mylar) or 3. Returns shape (..., k).
    """
    p = np.asarray(points, float)
    a = np.asarray(start, float)[..., None, :]
    u = np.asarray(end, float)[..., None, :] - a
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    v = p - a
    along = np.sum(v * u, axis=-1, keepdims=True)
    out: Array = np.linalg.norm(v - along * u, axis=-1)
    return out


def signed_extreme(x: ArrayLike, axis: int = -1) -> Array:
    """The entry of largest magnitude along ``axis``, sign kept (Tables 6-8/6-9 columns)."""
    a = np.asarray(x, float)
    k = np.expand_dims(np.argmax(np.abs(a), axis=axis), axis)
    out: Array = np.take_along_axis(a, k, axis=axis).squeeze(axis)
    return out
