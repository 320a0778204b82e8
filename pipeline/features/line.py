"""Line-of-translation estimation for prismatic joints, Section 4.3.2.3, (4.44)-(4.47).

The best line in the sense of squared perpendicular distances passes through
the centroid (4.45); its direction is the principal axis of the centered points,
the eigenvector of the largest eigenvalue of their scatter matrix (4.46). The
sign is chosen by (4.47) so the direction points toward increasing joint readings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.features.checks import principal_axes, spacing_warnings
from pipeline.kinematics.transforms import Array, ArrayLike


@dataclass(frozen=True)
class LineFit:
    """A fitted line-of-translation for one or many point sets.

    Attributes
    ----------
    direction : ndarray, shape (..., 3)
        Unit direction ``[a, b, c]`` of (4.44), toward increasing joint reading.
    point : ndarray, shape (..., 3)
        The centroid ``u_0`` of (4.45), a point on the line (cm).
    residuals : ndarray, shape (..., N)
        Perpendicular distance of each point from the line (cm), ≥ 0.
    travel : ndarray, shape (..., N)
        Coordinate of each point along ``direction``, measured from ``point`` (cm).
    warnings : tuple of str
        Violations of (B-1)/(B-2), prefixed by the set index.
    """

    direction: Array
    point: Array
    residuals: Array
    travel: Array
    warnings: tuple[str, ...]


def fit_line(points: ArrayLike) -> LineFit:
    """Line-of-translation by the principal axis method, (4.44)-(4.47).

    Parameters
    ----------
    points : array_like, shape (..., N, 3)
        Target positions in increasing joint-reading order (cm), N ≥ 3.

    Returns
    -------
    LineFit

    Raises
    ------
    FeatureError
        Fewer than 3 points, non-finite values, or all points coinciding.
    """
    # Eq. (4.45): u0 is the mean; Eq. (4.46): M is the scatter up to the factor 1/m
    p, u0, centered, _, vec = principal_axes(points, "line-of-translation", plane=False)
    v = vec[..., :, 2]  # largest eigenvalue
    ends = p[..., -1, :] - p[..., 0, :]
    # Eq. (4.47): only the sign matters, so |p_m − p_1| need not be divided out.
    v = v * np.where(np.einsum("...i,...i->...", v, ends) < 0.0, -1.0, 1.0)[..., None]
    travel = np.einsum("...ni,...i->...n", centered, v)
    residuals = np.linalg.norm(centered - travel[..., None] * v[..., None, :], axis=-1)
    extent = travel.max(-1) - travel.min(-1)
    # Per-coordinate noise: each squared distance sums two perpendicular components.
    noise = np.sqrt(np.mean(residuals**2, axis=-1) / 2.0)
    warnings = spacing_warnings(np.diff(travel, axis=-1), extent, noise, "travel", angular=False)
    return LineFit(
        direction=v, point=u0, residuals=residuals, travel=travel, warnings=tuple(warnings)
    )
