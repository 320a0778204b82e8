"""Accuracy of identified features, Section 6.6, (6.8)-(6.13) and Table 6-4.

* ``σ_E, σ_F`` (6.9)/(6.10): standard deviations of the plane slopes, i.e. of the
  plane's tilt (rad), from the in-plane spread of the points and the normal
  residual variance. We evaluate them in the in-plane principal axes, X along
  the least spread, so ``σ_E`` is the largest tilt deviation over all directions
  (the "maximum variance" the thesis computes exactly from (6.9)).
* ``σ_δ`` (6.11) for a full turn, and the thesis's empirical fit (6.12) for a
  sweep of ``X`` degrees: ``σ_n² / (R² n (.00244 X − .344))``.
* ``σ_c`` (6.13), the empirical (Monte-Carlo) fit for the center coordinates:
  ``σ_r² / (n (.00229 X − .313))``.

The constants .00244/.344 and .00229/.313 are Stone's, quoted as printed. (6.12)
is a linear fit in X of the least in-plane spread of a uniform arc,
``min(½(1 + sin X / X) − (sin(X/2) / (X/2))², ½(1 − sin X / X))``: both give
0.095 at 180°, 0.31/0.30 at 270° and 0.53/0.50 at 360°. In σ the fit is within
4.4 % on [180°, 360°], but it is low there (not "conservative" as stated) by up
to 4.4 % near 212°. The thesis states both fits for sweeps of at least 180°
(B-3, which :func:`~.circle.fit_circle` warns about). We evaluate them as
written and return NaN only where the denominator is not positive (X ≤ 141° for
(6.12), X ≤ 137° for (6.13)); for short sweeps use ``sigma_delta`` from
:func:`revolute_accuracy`, which is valid at any sweep.

**Planning a sweep** (issue 28, :mod:`pipeline.planning.sweeps`): :func:`sweep_accuracy`
predicts both accuracies of ``n`` points equally spaced over a planned sweep, by the
thesis's formulas where it states them (a sweep of at least 180°: (6.11) from a full
turn, else (6.12), and (6.13)), and where it is silent (under 180°) by the exact
linearised statistics of the same arc (:func:`arc_accuracy`: (6.9)/(6.10) and the
circle fit's center covariance); :func:`points_for_accuracy` is its inverse, the fewest
points for a wanted ``σ_δ`` and ``σ_c``. A sweep past a full turn is taken as a full
turn (the formulas were fitted up to 360°; more travel only repeats directions).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from pipeline.features.circle import CircleFit
from pipeline.features.plane import PlaneFit, frame_about
from pipeline.kinematics.transforms import Array, ArrayLike


@dataclass(frozen=True)
class FeatureAccuracy:
    """Accuracy statistics of a plane- and center-of-rotation (Tables 6-4, 6-5).

    Attributes
    ----------
    sigma_E, sigma_F : ndarray, shape (...)
        Slope standard deviations (6.9)/(6.10) along the least and the most
        in-plane spread of the points (rad).
    sigma_delta : ndarray, shape (...)
        Largest tilt standard deviation of the plane, ``max(σ_E, σ_F)`` (rad).
    sigma_delta_empirical : ndarray, shape (...)
        (6.12) with the measured sweep, radius and normal residual std (rad);
        meant for sweeps of at least 180°, NaN under 141°.
    sigma_c : ndarray, shape (...)
        (6.13) with the measured sweep and radial residual std (cm); meant
        for sweeps of at least 180°, NaN under 137°.
    normal_variance, radial_variance : ndarray, shape (...)
        Sample variances of the normal and radial residuals, Table 6-4 (cm²).
    sweep : ndarray, shape (...)
        Angle swept by the points, X of (6.12)/(6.13) (rad).
    """

    sigma_E: Array
    sigma_F: Array
    sigma_delta: Array
    sigma_delta_empirical: Array
    sigma_c: Array
    normal_variance: Array
    radial_variance: Array
    sweep: Array


def slope_sigmas(points: ArrayLike, normal: ArrayLike, sigma_n: ArrayLike) -> tuple[Array, Array]:
    """Slope standard deviations ``σ_E, σ_F`` of the regression (4.19), (6.8)-(6.10).

    Parameters
    ----------
    points : array_like, shape (..., N, 3)
        Target positions (cm).
    normal : array_like, shape (..., 3)
        Unit plane normal.
    sigma_n : array_like, shape (...)
        Standard deviation of the normal residuals (cm).

    Returns
    -------
    sigma_E, sigma_F : ndarray, shape (...)
        Radians (slopes ≪ 1); X is the in-plane axis of least spread, so σ_E ≥ σ_F.
    """
    p = np.asarray(points, float)
    c = p - p.mean(axis=-2, keepdims=True)  # x̂_j = x_j − x̄, ŷ_j = y_j − ȳ
    xy = np.einsum("...ni,...ij->...nj", c, frame_about(normal)[..., :, :2])
    _, axes = np.linalg.eigh(np.einsum("...ni,...nj->...ij", xy, xy))
    x, y = np.moveaxis(np.einsum("...ni,...ij->...nj", xy, axes), -1, 0)
    sxx, syy, sxy = (x * x).sum(-1), (y * y).sum(-1), (x * y).sum(-1)
    var_n = np.square(np.asarray(sigma_n, float))
    det = sxx * syy - sxy**2
    return np.sqrt(var_n * syy / det), np.sqrt(var_n * sxx / det)  # Eq. (6.9), (6.10)


def sigma_delta_full(sigma_n: ArrayLike, radius: ArrayLike, n: ArrayLike) -> Array:
    """Plane tilt standard deviation for a full 360° turn, (6.11) (rad).

    ``sigma_n`` and ``radius`` in cm, ``n`` the number of points; shapes broadcast.
    """
    s, r, m = (np.asarray(v, float) for v in (sigma_n, radius, n))
    return np.sqrt(2.0 * s**2 / (r**2 * m))  # Eq. (6.11)


def sigma_delta_partial(
    sigma_n: ArrayLike, radius: ArrayLike, n: ArrayLike, sweep: ArrayLike
) -> Array:
    """Largest plane tilt standard deviation for a partial sweep, (6.12) (rad).

    ``sweep`` in radians (X = its value in degrees); NaN where the denominator is ≤ 0.
    """
    s, r, m, x = (np.asarray(v, float) for v in (sigma_n, radius, n, sweep))
    den = r**2 * m * (0.00244 * np.degrees(x) - 0.344)  # Eq. (6.12), Stone's constants
    return np.sqrt(s**2 / np.where(den > 0, den, np.nan))


def sigma_center(sigma_r: ArrayLike, n: ArrayLike, sweep: ArrayLike) -> Array:
    """Largest center-coordinate standard deviation, (6.13) (cm).

    ``sigma_r`` in cm, ``sweep`` in radians; NaN where the denominator is ≤ 0.
    """
    s, m, x = (np.asarray(v, float) for v in (sigma_r, n, sweep))
    den = m * (0.00229 * np.degrees(x) - 0.313)  # Eq. (6.13), Stone's constants
    return np.sqrt(s**2 / np.where(den > 0, den, np.nan))


def revolute_accuracy(points: ArrayLike, plane: PlaneFit, circle: CircleFit) -> FeatureAccuracy:
    """All accuracy statistics of a revolute joint's features.

    Parameters
    ----------
    points : array_like, shape (..., N, 3)
        The target positions both fits were made from (cm).
    plane : PlaneFit
    circle : CircleFit

    Returns
    -------
    FeatureAccuracy
    """
    p = np.asarray(points, float)
    n = p.shape[-2]
    # "Sample variance" as the thesis says (6.8): 1/(N − 1) about the mean.
    var_n = np.var(plane.residuals, axis=-1, ddof=1)
    var_r = np.var(circle.residuals, axis=-1, ddof=1)
    sigma_e, sigma_f = slope_sigmas(p, plane.normal, np.sqrt(var_n))
    return FeatureAccuracy(
        sigma_E=sigma_e,
        sigma_F=sigma_f,
        sigma_delta=np.maximum(sigma_e, sigma_f),
        sigma_delta_empirical=sigma_delta_partial(np.sqrt(var_n), circle.radius, n, circle.sweep),
        sigma_c=sigma_center(np.sqrt(var_r), n, circle.sweep),
        normal_variance=var_n,
        radial_variance=var_r,
        sweep=circle.sweep,
    )


#: The fewest points per sweep: the thesis identified signatures "using as few as five
#: measurements per circle" (Section 6.4).
MIN_POINTS = 5
#: Most points per sweep a plan asks for (``simulate --points``' cap).
MAX_POINTS = 1000
_FULL_TURN = 2.0 * np.pi
_HALF_TURN = np.pi  # (6.12)/(6.13) are stated for sweeps of at least 180°
Law = Literal["(6.11)", "(6.12)", "arc"]


def arc_accuracy(
    sigma_n: float, sigma_r: float, radius: float, n: int, sweep: float
) -> tuple[float, float]:
    """Exact linearised ``σ_δ`` (rad, the largest of (6.9)/(6.10)) and ``σ_c`` (cm, the
    largest center-coordinate σ) of ``n`` points equally spaced over ``sweep`` rad (a
    full turn: ``n`` over 360°, none twice) on a circle of ``radius`` cm, with normal and
    radial residual σ ``sigma_n``, ``sigma_r`` (cm).

    The center: a radial residual ``w_j ≈ |p_j − c| − r`` has the gradient ``−(cos φ_j,
    sin φ_j, 1)`` in ``(c_x, c_y, r)``, so ``Cov = σ_r² (ΦᵀΦ)⁻¹`` with those rows; ``σ_c²``
    is the largest eigenvalue of its center block (the thesis's "maximum variance");
    a full turn gives ``2 σ_r² / n``, what (6.13) approximates by ``σ_r² / (.511 n)``.
    """
    full = sweep >= _FULL_TURN
    phi = np.linspace(0.0, _FULL_TURN if full else sweep, n, endpoint=not full)
    pts = radius * np.stack([np.cos(phi), np.sin(phi), np.zeros(n)], axis=-1)
    s_e, s_f = slope_sigmas(pts, np.array([0.0, 0.0, 1.0]), sigma_n)  # Eq. (6.9), (6.10)
    Phi = np.stack([np.cos(phi), np.sin(phi), np.ones(n)], axis=-1)
    cov = sigma_r**2 * np.linalg.inv(Phi.T @ Phi)
    return float(max(s_e, s_f)), float(np.sqrt(np.linalg.eigvalsh(cov[:2, :2])[-1]))


def sweep_accuracy(
    sigma_n: float, sigma_r: float, radius: float, n: int, sweep: float
) -> tuple[float, float, Law]:
    """Predicted ``σ_δ`` (rad) and ``σ_c`` (cm) of ``n`` points over a sweep of ``sweep``
    rad, and the law used: the thesis's (6.11) (a full turn) or (6.12) with (6.13) for a
    sweep of at least 180°, else ``"arc"`` (:func:`arc_accuracy`). Module docstring."""
    if sweep < _HALF_TURN:
        return (*arc_accuracy(sigma_n, sigma_r, radius, n, sweep), "arc")
    x = min(sweep, _FULL_TURN)
    c = float(sigma_center(sigma_r, n, x))  # Eq. (6.13)
    if sweep >= _FULL_TURN:
        return float(sigma_delta_full(sigma_n, radius, n)), c, "(6.11)"  # Eq. (6.11)
    return float(sigma_delta_partial(sigma_n, radius, n, x)), c, "(6.12)"  # Eq. (6.12)


def points_for_accuracy(
    sigma_n: float,
    sigma_r: float,
    radius: float,
    sweep: float,
    plane_sigma: float | None = None,
    center_sigma: float | None = None,
) -> int:
    """The fewest points (at least :data:`MIN_POINTS`) over a sweep of ``sweep`` rad whose
    :func:`sweep_accuracy` meets ``plane_sigma`` (rad) and ``center_sigma`` (cm), each
    when given; :data:`MAX_POINTS` + 1 when even that many do not. Both σ fall as
    ``1/√n`` ((6.11)-(6.13) exactly; the arc's nearly), so the search starts at the
    ``n`` that scaling predicts and steps to the first that meets both."""

    def meets(n: int) -> bool:
        d, c, _ = sweep_accuracy(sigma_n, sigma_r, radius, n, sweep)
        return (plane_sigma is None or d <= plane_sigma) and (
            center_sigma is None or c <= center_sigma
        )

    d0, c0, _ = sweep_accuracy(sigma_n, sigma_r, radius, MIN_POINTS, sweep)
    with np.errstate(over="ignore"):  # a σ of 1e-300 asks for infinitely many: the cap
        scale = max(
            float(np.square(np.float64(d0) / plane_sigma)) if plane_sigma else 0.0,
            float(np.square(np.float64(c0) / center_sigma)) if center_sigma else 0.0,
        )
    n = int(np.clip(np.ceil(MIN_POINTS * scale), MIN_POINTS, MAX_POINTS + 1))
    while n <= MAX_POINTS and not meets(n):
        n += 1
    while n > MIN_POINTS and meets(n - 1):
        n -= 1
    return n
