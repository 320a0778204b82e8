"""Input validation and the assumptions (B-1)-(B-3) of Section 4.3.2.1.

Bad input (too few points, NaN, collinear or coincident points) raises
:class:`~pipeline.errors.FeatureError`. Violated assumptions do not: the fits
still run and report them as warning strings, one per point set and assumption.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from pipeline.errors import FeatureError
from pipeline.kinematics.transforms import Array, ArrayLike

Mask = npt.NDArray[np.bool_]

#: Three points are the fewest that define a plane or a circle (4.26)-(4.29).
MIN_POINTS = 3

#: Below 10 points the sample variances behind (6.8)-(6.13) have at most 6 degrees
#: of freedom (3 fitted parameters), i.e. a relative standard error sqrt(2/6) ≈ 0.6:
#: the fit is fine but its accuracy statistics are not. The thesis used 50 to 100.
FEW_POINTS = 10

#: (B-1): noise "several orders of magnitude (typically > 3)" below the radius.
NOISE_RATIO_B1 = 1e-3

#: (B-3): revolute joints need at least 180 degrees of travel.
MIN_SWEEP_B3 = np.pi

#: (B-2): uniform indexing (4.5) gives equal steps. A step off the mean by half a
#: step cannot come from noise when (B-1) holds (angular noise ≲ σ/R ≤ 1e-3 rad
#: against steps of ~0.05 rad); it means missing, extra or reordered points.
STEP_DEVIATION_B2 = 0.5

#: Spread eigenvalue ratio λ_mid/λ_max below which points count as collinear.
#: eigh on the (4.18) sums is accurate to ~1e-16·λ_max, so 1e-12 sits 1e4 above
#: rounding; it is an in-plane spread of 1e-6 of the extent, while even a 1° arc
#: has a ratio of ~1e-5 (spread ratio ~X/4 for sweep X in rad).
COLLINEAR_RATIO = 1e-12

#: RMS spread below 1e-12 of the coordinate magnitude is rounding of the centroid:
#: the points coincide.
COINCIDENT_RATIO = 1e-12


def point_sets(points: ArrayLike, feature: str) -> Array:
    """Validate target positions and return them as float, shape (..., N, 3).

    Raises
    ------
    FeatureError
        Wrong shape, fewer than :data:`MIN_POINTS` points, or non-finite values.
    """
    p = np.asarray(points, dtype=float)
    if p.ndim < 2 or p.shape[-1] != 3:
        raise FeatureError(
            f"{feature}: target positions have the wrong shape",
            expected="an array of shape (..., N, 3) in cm",
            got=f"shape {p.shape}",
            fix="stack the measured positions as rows [x, y, z]",
        )
    n = p.shape[-2]
    if n < MIN_POINTS:
        raise FeatureError(
            f"{feature}: too few target positions",
            expected=f"at least {MIN_POINTS} points per set",
            got=f"{n} point{'s' if n != 1 else ''}",
            fix="index the joint to more positions (the thesis uses 50 to 100)",
        )
    bad = ~np.isfinite(p).all(axis=(-1, -2))
    if bad.any():
        raise FeatureError(
            f"{feature}: target positions contain NaN or infinity",
            expected="finite coordinates",
            got=f"non-finite values in {_where(bad)}",
            fix="drop the failed measurements before fitting",
        )
    return p


def scatter(centered: Array) -> Array:
    """Sum of outer products Σ p̂ p̂ᵀ of centered points, shape (..., 3, 3)."""
    return np.einsum("...ni,...nj->...ij", centered, centered)


def require_spread(points: Array, eigenvalues: ArrayLike, feature: str, plane: bool) -> None:
    """Raise FeatureError for coincident points or, if ``plane``, collinear ones.

    ``eigenvalues`` are the ascending eigenvalues (..., 3) of :func:`scatter`.
    """
    eig = np.asarray(eigenvalues, float)
    n = points.shape[-2]
    size = np.max(np.abs(points), axis=(-1, -2))
    # A 1 cm floor on the scale, so sets at the sensor origin are not judged against 0.
    coincident = np.sqrt(eig[..., 2] / n) <= COINCIDENT_RATIO * np.maximum(size, 1.0)
    if coincident.any():
        raise FeatureError(
            f"{feature}: all target positions coincide",
            expected="points spread along the joint motion",
            got=f"one repeated position in {_where(coincident)}",
            fix="check that the joint actually moved between measurements",
        )
    if plane:
        collinear = eig[..., 1] <= COLLINEAR_RATIO * eig[..., 2]
        if collinear.any():
            raise FeatureError(
                f"{feature}: target positions are collinear",
                expected="points on an arc, which span a plane",
                got=f"points on a straight line in {_where(collinear)}",
                fix="use fit_line for a prismatic joint, or a target off the joint axis",
            )


def principal_axes(
    points: ArrayLike, feature: str, plane: bool
) -> tuple[Array, Array, Array, Array, Array]:
    """Validated points, centroid, centered points and the eigen-decomposition of their scatter.

    Returns ``(p (..., N, 3), mean (..., 3), centered (..., N, 3), eigenvalues (..., 3)
    ascending, eigenvectors (..., 3, 3) as columns)``; raises like :func:`point_sets`
    and :func:`require_spread`.
    """
    p = point_sets(points, feature)
    mean = p.mean(axis=-2)
    centered = p - mean[..., None, :]
    eig, vec = np.linalg.eigh(scatter(centered))
    require_spread(p, eig, feature, plane=plane)
    return p, mean, centered, eig, vec


def label(index: tuple[int, ...]) -> str:
    """Prefix naming one point set of a batch ('' for an unbatched call)."""
    return f"point set {index}: " if index else ""


def collect(mask: Mask, message: Callable[[tuple[int, ...]], str]) -> list[str]:
    """One message per True entry of ``mask`` (shape = batch shape), prefixed by its set."""
    return [label(i) + message(i) for i in (tuple(int(v) for v in r) for r in np.argwhere(mask))]


def spacing_warnings(
    steps: Array, extent: Array, noise: Array, scale_name: str, angular: bool
) -> list[str]:
    """Warnings for (B-1) and (B-2) shared by circle and line fits.

    Parameters
    ----------
    steps : ndarray, shape (..., N-1)
        Signed steps between consecutive points along the motion (rad or cm).
    extent : ndarray, shape (...)
        Radius (revolute) or travel (prismatic), cm.
    noise : ndarray, shape (...)
        Largest residual standard deviation, cm.
    scale_name : str
        What ``extent`` is, for the message.
    angular : bool
        ``steps`` are angles in rad (shown in degrees), else lengths in cm.
    """
    n = steps.shape[-1] + 1
    out = collect(
        noise > NOISE_RATIO_B1 * extent,
        lambda i: (
            f"B-1: residual noise {noise[i]:.3g} cm is not 1000x below the {scale_name} "
            f"{extent[i]:.3g} cm; the features are less accurate"
        ),
    )
    if n < FEW_POINTS:
        out += collect(
            np.ones(steps.shape[:-1], bool),
            lambda i: f"B-2: only {n} points; accuracy statistics need at least {FEW_POINTS}",
        )
    mean = steps.mean(axis=-1)
    uneven = np.max(np.abs(steps - mean[..., None]), axis=-1) > STEP_DEVIATION_B2 * np.abs(mean)
    scale, unit = (np.degrees(1.0), "°") if angular else (1.0, " cm")
    out += collect(
        uneven,
        lambda i: (
            "B-2: joint positions are not uniformly spaced or not in increasing order "
            f"(steps from {scale * steps[i].min():.3g}{unit} to {scale * steps[i].max():.3g}"
            f"{unit}, mean {scale * mean[i]:.3g}{unit})"
        ),
    )
    return out


def _where(mask: Mask) -> str:
    idx = [tuple(int(v) for v in i) for i in np.argwhere(mask)]
    if idx == [()]:
        return "the point set"
    shown = ", ".join(map(str, idx[:5])) + (", ..." if len(idx) > 5 else "")
    return f"point set(s) {shown}"
