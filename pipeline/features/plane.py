"""Plane-of-rotation estimation, Section 4.3.2.1.

Two estimators of the plane ``A x + B y + C z + D = 0`` (4.6) through the
positions of a target on a revolute joint:

* :func:`fit_plane_eigen`, the average-gradient eigenvalue method (4.15)-(4.18);
* :func:`fit_plane_lsq`, the repeated linear least-squares method (4.19)-(4.32).

Both minimise the squared perpendicular distances; the fixed point of the
repeated regression is an eigenvector of (4.18), so both give the same plane.
The normal is returned as a unit vector oriented so that the points, taken in
increasing joint-reading order, rotate positively (right-handed) about it
(:func:`orient_normal`).

Deviations from the OCR'd text, each checked numerically in the tests:

* (4.15): with the constraint (4.14) the aggregate error is ``Ξ = λ``, not ``λ m``.
* (4.21): ``Θ = [E F G]ᵀ`` (G is missing); (4.23): ``Θ = (ΦᵀΦ)⁻¹ Φᵀ Z``.
* (4.26)/(4.30): with ``R = [n o a]`` (columns) the frame coordinates are
  ``p⁰ = Rᵀ p`` and the normal maps back as ``R [A⁰ B⁰ C⁰]ᵀ``.
* (4.19) gives ``E x + F y − z + G = 0``, whose normal ``[E, F, −1]`` points
  against the frame's Z; we use ``[−E, −F, 1]`` so the sense of ``a`` is kept.
* (4.31) is lost in print; it is ``[A B C]ᵀ / w`` with ``w`` from (4.32).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.features.checks import collect, principal_axes
from pipeline.kinematics.transforms import Array, ArrayLike

#: Stop the repeated regression when the normal moves by less than this angle
#: (rad). The error contracts by λ_min/λ_plane ~ (σ/R)² per pass under (B-1), so
#: 1e-12 rad (~1e4 ulps) is reached in 2-4 passes, as the thesis reports.
LSQ_TOL = 1e-12

#: Safety cap on passes; only data far outside (B-1)-(B-3) needs more than 4.
LSQ_MAX_ITER = 50


@dataclass(frozen=True)
class PlaneFit:
    """A fitted plane-of-rotation for one or many point sets.

    Attributes
    ----------
    normal : ndarray, shape (..., 3)
        Unit normal ``[A, B, C]``; the motion is a positive rotation about it.
    offset : ndarray, shape (...)
        ``D`` of (4.6) with the unit normal: ``normal · p + offset = 0`` (cm).
    point : ndarray, shape (..., 3)
        The centroid of the points, which lies on the plane (4.17) (cm).
    residuals : ndarray, shape (..., N)
        Signed distance of each point from the plane along ``normal`` (cm).
    iterations : ndarray of int, shape (...)
        Regression passes of (4.19)-(4.32); 0 for the eigenvalue method.
    warnings : tuple of str
        Non-fatal problems (e.g. no convergence), prefixed by the set index.
    """

    normal: Array
    offset: Array
    point: Array
    residuals: Array
    iterations: Array
    warnings: tuple[str, ...]


def frame_about(normal: ArrayLike) -> Array:
    """Right-handed rotation ``[n o a]`` (columns) whose Z axis is ``normal``.

    ``n`` and ``o`` are arbitrary, as (4.34) and the repeated step of 4.3.2.1 allow.

    Parameters
    ----------
    normal : array_like, shape (..., 3)

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
    """
    a = np.asarray(normal, float)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    # Cross with the coordinate axis least aligned with a: |a_k| ≤ 1/√3 keeps |e_k × a| ≥ √(2/3).
    e = np.eye(3)[np.argmin(np.abs(a), axis=-1)]
    n = np.cross(e, a)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.stack([n, np.cross(a, n), a], axis=-1)


def orient_normal(normal: ArrayLike, points: ArrayLike) -> Array:
    """Flip normals so the ordered points rotate positively about them.

    The sign is that of the normal against the vector area
    ``½ Σ_j p̂_j × p̂_{j+1}`` of the closed polygon through the points in order.
    For three points this is the triangle rule (4.28) with ``q_k < q_l < q_m``;
    using all points makes it robust to noise and to sweeps of 360° or more.

    Parameters
    ----------
    normal : array_like, shape (..., 3)
    points : array_like, shape (..., N, 3)
        Target positions in increasing joint-reading order (cm).

    Returns
    -------
    normal : ndarray, shape (..., 3)
    """
    a = np.asarray(normal, float)
    p = np.asarray(points, float)
    c = p - p.mean(axis=-2, keepdims=True)
    area = 0.5 * np.cross(c, np.roll(c, -1, axis=-2)).sum(axis=-2)
    sign = np.where(np.einsum("...i,...i->...", area, a) < 0.0, -1.0, 1.0)
    return a * sign[..., None]


def fit_plane_eigen(points: ArrayLike) -> PlaneFit:
    """Plane-of-rotation by the eigenvalue method, (4.15)-(4.18).

    Parameters
    ----------
    points : array_like, shape (..., N, 3)
        Target positions in increasing joint-reading order (cm), N ≥ 3.

    Returns
    -------
    PlaneFit
        ``iterations`` is 0. The sum of squared residuals equals the smallest
        eigenvalue of (4.18).

    Raises
    ------
    FeatureError
        Fewer than 3 points, non-finite values, or collinear/coincident points.
    """
    # Eq. (4.18): eigenvectors of the scatter, ascending eigenvalues
    p, mean, centered, _, vec = principal_axes(points, "plane-of-rotation", plane=True)
    normal = orient_normal(vec[..., :, 0], p)  # smallest eigenvalue's eigenvector
    return _result(p, mean, centered, normal, np.zeros(p.shape[:-2], int), [])


def fit_plane_lsq(
    points: ArrayLike, *, tol: float = LSQ_TOL, max_iter: int = LSQ_MAX_ITER
) -> PlaneFit:
    """Plane-of-rotation by repeated linear least squares, (4.19)-(4.32).

    The first frame ``C_0`` (4.26)-(4.29) comes from three mutually distant
    points: the farthest pair and the point farthest from the line through it,
    taken in joint order ``k < l < m``. Each pass regresses the frame Z
    coordinate on X, Y and 1 (4.19)-(4.23), maps the normal back (4.31)-(4.32)
    and builds the next frame about it, until ``atan(hypot(E, F)) ≤ tol``.

    The points are centered on their centroid before the regression (the thesis
    keeps the sensor origin). Slopes ``E, F`` of a regression with an intercept
    do not depend on that shift, and centering keeps the regression well
    conditioned far from the sensor.

    Parameters
    ----------
    points : array_like, shape (..., N, 3)
        Target positions in increasing joint-reading order (cm), N ≥ 3.
    tol : float
        Convergence angle between successive normals (rad).
    max_iter : int
        Most passes; sets that do not converge get a warning.

    Returns
    -------
    PlaneFit

    Raises
    ------
    FeatureError
        Fewer than 3 points, non-finite values, or collinear/coincident points.
    """
    p, mean, centered, _, _ = principal_axes(points, "plane-of-rotation", plane=True)
    R = _initial_frame(p)
    normal = R[..., :, 2]
    iterations = np.zeros(p.shape[:-2], int)
    done = np.zeros(p.shape[:-2], bool)
    for it in range(1, max_iter + 1):
        local = np.einsum("...ji,...nj->...ni", R, centered)  # Eq. (4.30)
        # Eq. (4.23) on centered data: Φ = [x y] (4.24); the intercept G only shifts D.
        E, F = np.moveaxis(least_squares(local[..., :2], local[..., 2]), -1, 0)
        w = np.sqrt(E * E + F * F + 1.0)  # Eq. (4.32)
        new = (
            np.einsum("...ij,...j->...i", R, np.stack([-E, -F, np.ones_like(E)], -1)) / w[..., None]
        )  # Eq. (4.31), sense of a kept
        normal = np.where(done[..., None], normal, new)
        iterations = np.where(done, iterations, it)
        done |= np.arctan(np.hypot(E, F)) <= tol
        if done.all():
            break
        R = frame_about(normal)
    warnings = collect(
        ~done,
        lambda i: (
            f"repeated least squares did not converge to {tol:g} rad in {max_iter} "
            "passes; data are far from (B-1)-(B-3), compare with fit_plane_eigen"
        ),
    )
    return _result(p, mean, centered, orient_normal(normal, p), iterations, warnings)


def least_squares(phi: Array, out: Array) -> Array:
    """Θ = (ΦᵀΦ)⁻¹ Φᵀ Z of (4.23), solved through a QR factorisation of Φ.

    Same Θ as the normal equations, which square the condition number of Φ:
    on a 5° arc that costs about three digits of the center.

    Parameters
    ----------
    phi : ndarray, shape (..., N, k)
        Rows are the information vectors φ_j (4.24).
    out : ndarray, shape (..., N)
        Outputs, Z (4.25) or W (4.40).

    Returns
    -------
    theta : ndarray, shape (..., k)
    """
    q, r = np.linalg.qr(phi)
    return np.linalg.solve(r, np.einsum("...nk,...n->...k", q, out)[..., None])[..., 0]


#: Sets of at most this many points take the farthest pair from the whole N×N distance
#: array, batched; larger sets one at a time from the blocks that can hold it.
DENSE_MAX_POINTS = 64
#: Points per block of :func:`farthest_pair`: consecutive points of a sweep are close,
#: so a block's bounding sphere is small against the sweep.
_BLOCK = 8
#: Relative slack of the block bounds: a bound is a sum of a few rounded distances
#: (relative error ~1e-15), so 1e-9 can never prune the block holding the farthest pair.
_BOUND_SLACK = 1e-9
#: Block pairs whose distances are evaluated at once (4096 × 64 pairs, 6 MB).
_PAIRS_PER_SLICE = 4096


def farthest_pair(p: Array) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i, j)``, ``i < j``, of the two mutually farthest points of each set.

    The pair ``argmax`` of the squared distances ``((p_i − p_j)²).sum()`` would pick over
    the whole N×N array (ties: the first in row-major order), the same values bit for bit,
    but for sets larger than :data:`DENSE_MAX_POINTS` without building that array: the
    distances are evaluated only between blocks of consecutive points whose bounding
    spheres can be that far apart (:func:`_farthest_pair_blocks`). Memory: the indices
    of the kept block pairs and slices of a few MB. Time: (N/8)² sphere bounds, cheap
    (1,600 points: 40,000), plus the kept blocks' distances, about linear in N on an arc
    and O(N^1.5) on a full circle, where every point has an antipode. Measured on 1,600
    points over 300°: 20 ms against 250 ms for the N×N array.

    Parameters
    ----------
    p : ndarray, shape (..., N, 3)

    Returns
    -------
    first, second : ndarray of int, shape (...)
    """
    n_pts = p.shape[-2]
    if n_pts <= DENSE_MAX_POINTS:
        d2 = ((p[..., :, None, :] - p[..., None, :, :]) ** 2).sum(-1)
        first, second = np.divmod(d2.reshape(*d2.shape[:-2], -1).argmax(-1), n_pts)
        return first, second
    flat = p.reshape(-1, n_pts, 3)
    pairs = np.array([_farthest_pair_blocks(x) for x in flat], int).reshape(*p.shape[:-2], 2)
    return pairs[..., 0], pairs[..., 1]


def _farthest_pair_blocks(p: Array) -> tuple[int, int]:
    """:func:`farthest_pair` of one set (N, 3), from the blocks that can hold the pair."""
    n = len(p)
    # A lower bound of the largest distance: from the point farthest from the centroid.
    far = int(((p - p.mean(axis=0)) ** 2).sum(-1).argmax())
    lower = float(np.sqrt(((p - p[far]) ** 2).sum(-1).max()))
    n_blocks = -(-n // _BLOCK)
    idx = np.minimum(np.arange(n_blocks * _BLOCK).reshape(n_blocks, _BLOCK), n - 1)
    centers = p[idx].mean(axis=1)
    radii = np.sqrt(((p[idx] - centers[:, None, :]) ** 2).sum(-1)).max(axis=1)
    # Two points of blocks a, b are at most |c_a − c_b| + r_a + r_b apart; the bounds of
    # block pairs a ≤ b, in slices of about a million.
    step = max(1, (1 << 20) // n_blocks)
    kept = []
    for lo in range(0, n_blocks, step):
        c = centers[lo : lo + step]
        bound = np.sqrt(((c[:, None, :] - centers[None, :, :]) ** 2).sum(-1))
        bound += radii[lo : lo + step, None] + radii[None, :]
        keep = bound * (1.0 + _BOUND_SLACK) >= lower * (1.0 - _BOUND_SLACK)
        a, b = np.nonzero(np.triu(keep, lo))
        kept.append((a + lo, b))
    a, b = (np.concatenate(x) for x in zip(*kept, strict=True))
    best, key = 0.0, 0  # all points coinciding: the N×N argmax is (0, 0)
    for lo in range(0, len(a), _PAIRS_PER_SLICE):
        ra, rb = idx[a[lo : lo + _PAIRS_PER_SLICE]], idx[b[lo : lo + _PAIRS_PER_SLICE]]
        rows = np.broadcast_to(ra[:, :, None], (len(ra), _BLOCK, _BLOCK))
        cols = np.broadcast_to(rb[:, None, :], rows.shape)
        d2 = ((p[rows] - p[cols]) ** 2).sum(-1)  # the same expression as the N×N array's
        d2 = np.where(rows < cols, d2, -1.0)  # each pair once, as (i, j) with i < j
        top = d2.max()
        if top > best or (top == best and top > 0.0):  # ties: the first in row-major order
            k = int((rows * n + cols)[d2 == top].min())
            best, key = top, (k if top > best else min(key, k))
    return key // n, key % n


def _initial_frame(p: Array) -> Array:
    """Frame ``C_0`` of (4.26)-(4.29) from three mutually distant points, (..., 3, 3)."""
    first, second = farthest_pair(p)
    pa = np.take_along_axis(p, first[..., None, None], axis=-2)
    pb = np.take_along_axis(p, second[..., None, None], axis=-2)
    third = np.linalg.norm(np.cross(pb - pa, p - pa), axis=-1).argmax(-1)
    idx = np.sort(np.stack([first, second, third], axis=-1), axis=-1)  # q_k < q_l < q_m
    pk, pl, pm = np.moveaxis(np.take_along_axis(p, idx[..., None], axis=-2), -2, 0)
    n = (pl - pk) / np.linalg.norm(pl - pk, axis=-1, keepdims=True)  # Eq. (4.27)
    a = np.cross(pl - pk, pm - pk)
    a /= np.linalg.norm(a, axis=-1, keepdims=True)  # Eq. (4.28)
    return np.stack([n, np.cross(a, n), a], axis=-1)  # Eq. (4.29), (4.26)


def _result(
    p: Array, mean: Array, centered: Array, normal: Array, iterations: Array, warnings: list[str]
) -> PlaneFit:
    return PlaneFit(
        normal=normal,
        offset=-np.einsum("...i,...i->...", normal, mean),  # Eq. (4.17)
        point=mean,
        residuals=np.einsum("...ni,...i->...n", centered, normal),  # ξ_j of (4.7), unit normal
        iterations=iterations,
        warnings=tuple(warnings),
    )
