"""Center-of-rotation estimation, Section 4.3.2.2, (4.33)-(4.43).

The points are expressed in a frame ``C`` whose Z axis is the plane normal
(4.34)-(4.35), so their X, Y coordinates are the projection onto the plane.
The circle ``x² + y² = A x + B y + C`` (4.37) is fitted by linear least squares
(4.23 with Z replaced by W), the data are translated by the new center
(4.41)-(4.42), and the fit is repeated.

Deviations from the OCR'd text:

* (4.36) prints ``z_c = D / w``. With (4.6), points on the plane satisfy
  ``a · p = −D / w``, so ``z_c = −D / w`` (``−offset`` for a unit normal).
* (4.35) reads ``Rᵀ p`` for ``R = [n o a]`` (columns), as in :mod:`.plane`.
* The algebraic residual ``(x − g)² + (y − h)² − r²`` of (4.40) does not change
  when data and circle are translated together, so the fit is the same circle
  in every translated frame: the repetition (4.41)-(4.42) stops after the second
  pass, which moves the center only by rounding. We keep it as the thesis does,
  starting from the centroid (not the sensor origin) for conditioning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import FeatureError
from pipeline.features.checks import MIN_SWEEP_B3, collect, point_sets, spacing_warnings
from pipeline.features.plane import PlaneFit, fit_plane_eigen, frame_about, least_squares
from pipeline.kinematics.transforms import Array, ArrayLike

#: Stop when a pass moves the center by less than this fraction of the RMS radius.
#: Passes after the first move it by rounding only (~1e-15 relative); 1e-12 is
#: well above that and far below any measurement accuracy.
CIRCLE_TOL = 1e-12

#: Safety cap on passes; two are needed in practice (see module docstring).
CIRCLE_MAX_ITER = 20


@dataclass(frozen=True)
class CircleFit:
    """A fitted center-of-rotation (circle in the plane-of-rotation).

    Attributes
    ----------
    center : ndarray, shape (..., 3)
        Center of the circle, on the fitted plane, in sensor coordinates (cm).
    radius : ndarray, shape (...)
        Circle radius (cm).
    normal : ndarray, shape (..., 3)
        Unit plane normal used for the projection (positive sense of rotation).
    residuals : ndarray, shape (..., N)
        Radial residuals: in-plane distance of each projected point from the
        center minus the radius (cm), positive outside the circle.
    sweep : ndarray, shape (...)
        Angle swept by the points about the center, X of (6.12)/(6.13) (rad).
    iterations : ndarray of int, shape (...)
        Passes of (4.37)-(4.42).
    warnings : tuple of str
        Violations of (B-1)-(B-3) and plane warnings, prefixed by the set index.
    """

    center: Array
    radius: Array
    normal: Array
    residuals: Array
    sweep: Array
    iterations: Array
    warnings: tuple[str, ...]


def fit_circle(
    points: ArrayLike,
    plane: PlaneFit | None = None,
    *,
    tol: float = CIRCLE_TOL,
    max_iter: int = CIRCLE_MAX_ITER,
) -> CircleFit:
    """Center-of-rotation by repeated linear least squares, (4.33)-(4.43).

    Parameters
    ----------
    points : array_like, shape (..., N, 3)
        Target positions in increasing joint-reading order (cm), N ≥ 3.
    plane : PlaneFit, optional
        Plane-of-rotation of the same points; :func:`fit_plane_eigen` if omitted.
    tol : float
        Convergence: center step below ``tol`` times the RMS radius.
    max_iter : int
        Most passes.

    Returns
    -------
    CircleFit

    Raises
    ------
    FeatureError
        Bad points (see :func:`fit_plane_eigen`) or a plane of another batch shape.
    """
    p = point_sets(points, "center-of-rotation")
    plane = fit_plane_eigen(p) if plane is None else plane
    if plane.normal.shape != p.shape[:-2] + (3,):
        raise FeatureError(
            "center-of-rotation: plane does not match the points",
            expected=f"a PlaneFit with normal of shape {p.shape[:-2] + (3,)}",
            got=f"normal of shape {plane.normal.shape}",
            fix="fit the plane on the same point array",
        )
    R = frame_about(plane.normal)  # Eq. (4.34)
    local = np.einsum("...ji,...nj->...ni", R, p)  # Eq. (4.35), p× = Rᵀ p
    xs, ys = local[..., 0], local[..., 1]
    z_c = -plane.offset  # Eq. (4.36), sign corrected (module docstring)
    g, h = xs.mean(-1), ys.mean(-1)
    scale = np.sqrt(np.mean((xs - g[..., None]) ** 2 + (ys - h[..., None]) ** 2, axis=-1))
    r2 = np.zeros_like(g)
    iterations = np.zeros(g.shape, int)
    done = np.zeros(g.shape, bool)
    for it in range(1, max_iter + 1):
        x, y = xs - g[..., None], ys - h[..., None]  # Eq. (4.41), (4.42)
        w = x * x + y * y  # Eq. (4.37)
        phi = np.stack([x, y, np.ones_like(x)], axis=-1)  # Eq. (4.38)
        A, B, C = np.moveaxis(least_squares(phi, w), -1, 0)  # Eq. (4.23), Z -> W; Θ of (4.39)
        # (4.33) expanded: A = 2g, B = 2h, C = r² − g² − h² in the translated frame.
        g = np.where(done, g, g + A / 2)
        h = np.where(done, h, h + B / 2)
        r2 = np.where(done, r2, C + (A * A + B * B) / 4)
        iterations = np.where(done, iterations, it)
        done |= np.hypot(A, B) / 2 <= tol * scale
        if done.all():
            break
    radius = np.sqrt(r2)
    center = np.einsum("...ij,...j->...i", R, np.stack([g, h, z_c], axis=-1))  # Eq. (4.43)
    dx, dy = xs - g[..., None], ys - h[..., None]
    residuals = np.hypot(dx, dy) - radius[..., None]
    steps = np.arctan2(
        dx[..., :-1] * dy[..., 1:] - dy[..., :-1] * dx[..., 1:],
        dx[..., :-1] * dx[..., 1:] + dy[..., :-1] * dy[..., 1:],
    )
    turned = np.concatenate([np.zeros_like(steps[..., :1]), np.cumsum(steps, axis=-1)], axis=-1)
    sweep = turned.max(-1) - turned.min(-1)
    noise = np.maximum(np.std(plane.residuals, axis=-1, ddof=1), np.std(residuals, axis=-1, ddof=1))
    warnings = list(plane.warnings)
    warnings += collect(
        ~done, lambda i: f"circle fit did not converge in {max_iter} passes; check the points"
    )
    warnings += spacing_warnings(steps, radius, noise, "radius", angular=True)
    # The measured sweep errs by ~σ/R at each end: allow 3 of that before warning,
    # so a joint with exactly 180° of travel is not flagged at random.
    warnings += collect(
        sweep < MIN_SWEEP_B3 - 3.0 * noise / radius,
        lambda i: (
            f"B-3: sweep {np.degrees(sweep[i]):.1f} deg is under 180 deg; the features "
            "are less accurate and (6.12)/(6.13) do not apply"
        ),
    )
    return CircleFit(
        center=center,
        radius=radius,
        normal=plane.normal,
        residuals=residuals,
        sweep=sweep,
        iterations=iterations,
        warnings=tuple(warnings),
    )
