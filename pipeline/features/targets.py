"""Several targets in one sweep: which are well conditioned, and their common feature.

A nest carries several targets (reflectors) that sweep together about (along) one
joint axis. Each is fitted on its own (plane and circle, or line); a target is used
when its fit can show the joint's motion:

* revolute: it moves (spread of its positions) and its radius exceeds both
  :data:`MIN_RADIUS_CM` and :data:`RADIUS_SIGMAS` times its point noise σ. A target on
  (or near) the axis barely moves: its plane normal is noise (σ_δ ≈ σ / (R·√N)).
* prismatic: its travel exceeds the same bound (every target of a link travels alike).

Point noise σ: the recorded one (``sigma_cm``, or √(trace(cov)/3)), median over the
target's points; without any (sonic), the fit's own residual scatter.

The used targets combine into one feature (exact when the data are): the common axis
is the weighted mean of their oriented normals (directions), weights
``N·R²/σ²`` (revolute: the plane tilt variance is ∝ σ²/(N·R²), (6.11)) or ``N/σ²``
(prismatic); the axis line passes through the weighted mean (``N/σ²``) of their
centres, and the origin is the best-conditioned target's centre moved onto that line
(along the axis: its plane, as with one target). X points at the best target's first
position. One used target gives exactly its own fit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.kinematics.transforms import angle_between

#: A target must move / sit at least this far from the axis (cm): far above a tracker's
#: or the sonic rig's noise, far below any real target radius (10-40 cm in the thesis).
MIN_RADIUS_CM = 1.0
#: ... and this many point σ: the plane tilt σ_δ ≈ σ / (R √N) stays below 0.05 / √N rad.
RADIUS_SIGMAS = 20.0
#: σ used as a weight floor (cm), for exact data (σ = 0) only.
SIGMA_FLOOR_CM = 1e-9


@dataclass(frozen=True)
class TargetFit:
    """One target's fit in one sweep: ``row`` the features row it alone would give."""

    target: str
    n_points: int
    sigma_cm: float
    row: dict[str, Any]

    def vec(self, key: str) -> np.ndarray:
        return np.asarray(self.row[key], float)

    @property
    def extent_cm(self) -> float:
        r = self.row
        return float(r["travel_cm"] if r["radius"] is None else r["radius"])

    def weight(self, prismatic: bool) -> float:
        """Weight of the target's axis direction in the combined axis."""
        s2 = max(self.sigma_cm, SIGMA_FLOOR_CM) ** 2
        return self.n_points / s2 * (1.0 if prismatic else self.extent_cm**2)


def bound_cm(sigma_cm: float, floor_cm: float = MIN_RADIUS_CM) -> float:
    """Least radius (travel) of a usable target with point noise ``sigma_cm``; ``floor_cm``
    0 for a sweep's only target (no other to prefer: a small robot's, e.g. SScanSS-2's
    two-link example with radii of 1-2 mm, is judged by its noise alone)."""
    return max(floor_cm, RADIUS_SIGMAS * sigma_cm)


def why_not_usable(
    spread_cm: float, sigma_cm: float, prismatic: bool, floor_cm: float = MIN_RADIUS_CM
) -> str | None:
    """Why a target whose positions spread ``spread_cm`` (largest distance from their mean)
    cannot be fitted, or None."""
    if spread_cm * 2.0 < bound_cm(sigma_cm, floor_cm):  # an arc of radius R spans up to 2R
        what = "travel" if prismatic else "motion (on or near the axis)"
        return (
            f"too little {what}: its positions lie within {spread_cm:.3g} cm of their mean "
            f"(needs {bound_cm(sigma_cm, floor_cm):.3g} cm = max({floor_cm:g} cm, "
            f"{RADIUS_SIGMAS:g} σ) with σ = {sigma_cm:.3g} cm)"
        )
    return None


def why_ill_conditioned(
    fit: TargetFit, prismatic: bool, floor_cm: float = MIN_RADIUS_CM
) -> str | None:
    """Why a fitted target is not used, or None."""
    need = bound_cm(fit.sigma_cm, floor_cm)
    if fit.extent_cm > need:
        return None
    what = "travel" if prismatic else "radius"
    where = "" if prismatic else " (on or near the axis)"
    return (
        f"{what} {fit.extent_cm:.3g} cm{where} not above {need:.3g} cm = "
        f"max({floor_cm:g} cm, {RADIUS_SIGMAS:g} σ) with σ = {fit.sigma_cm:.3g} cm"
    )


def _mean_direction(vectors: list[np.ndarray], weights: np.ndarray) -> np.ndarray:
    v = np.einsum("k,ki->i", weights, np.array(vectors))
    return v / np.linalg.norm(v)


def combine(fits: list[TargetFit], prismatic: bool) -> dict[str, Any]:
    """The features row of the used targets ``fits`` (best-conditioned first)."""
    best = fits[0]
    if len(fits) == 1:
        return dict(best.row)
    w = np.array([f.weight(prismatic) for f in fits])
    row = dict(best.row)
    axis = _mean_direction([f.vec("axis") for f in fits], w)
    row["axis"] = axis
    if prismatic:
        from pipeline.features.plane import frame_about

        row["first"] = best.vec("center") + frame_about(axis)[:, 0]
        return row
    row["eigen"] = _mean_direction([f.vec("eigen") for f in fits], w)
    row["lsq"] = _mean_direction([f.vec("lsq") for f in fits], w)
    row["angle"] = float(np.degrees(angle_between(row["eigen"], row["lsq"])))
    wc = np.array([f.n_points / max(f.sigma_cm, SIGMA_FLOOR_CM) ** 2 for f in fits])
    mean_c = np.einsum("k,ki->i", wc / wc.sum(), np.array([f.vec("center") for f in fits]))
    c = best.vec("center")
    d = mean_c - c
    row["center"] = c + d - (d @ axis) * axis  # onto the common line, in best's plane
    return row
