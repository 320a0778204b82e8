"""Accuracy of the feature fits against Section 6.6's formulas (6.9)-(6.13), by simulation.

For every sweep X, number of points N and noise σ: ``trials`` point sets on a
circle of radius R (angles ``linspace(0, X, N)``, as the session planner spaces
a sweep; isotropic Gaussian noise σ per coordinate, so σ_n = σ_r = σ), fitted
with the pipeline's plane (repeated least squares) and circle. The empirical
"largest" standard deviations are the square roots of the largest eigenvalue
of the 2 × 2 covariance of the tilt (normal's in-plane components, rad) and of
the in-plane center error (cm) over the trials. Stone fitted
``σ² / (R² n σ_δ²) = .00244 X − .344`` (6.12) and
``σ² / (n σ_c²) = .00229 X − .313`` (6.13); the same linear least-squares fit of
our empirical values gives our own constants.
"""

from __future__ import annotations

import sys
import time
import zlib
from dataclasses import dataclass
from typing import TextIO

import numpy as np

from pipeline.features.accuracy import (
    revolute_accuracy,
    sigma_center,
    sigma_delta_full,
    sigma_delta_partial,
)
from pipeline.features.circle import fit_circle
from pipeline.features.plane import fit_plane_lsq
from pipeline.kinematics.transforms import Array
from pipeline.progress import Progress

SWEEPS_DEG = (180.0, 240.0, 300.0, 360.0)
POINTS = (20, 50, 100)
SIGMAS_CM = (0.005, 0.02, 0.05)
RADIUS_CM = 40.0
TRIALS = 1000
#: Point sets per fit call: the plane fit's first frame builds an (N, N) distance
#: table per set, 250 × 100 × 100 × 3 doubles = 60 MB.
CHUNK = 250
STONE_612 = (0.00244, 0.344)
STONE_613 = (0.00229, 0.313)


@dataclass(frozen=True)
class FeatureStudyResult:
    """One row per (X, N, σ) configuration; arrays of shape (C,)."""

    sweep_deg: Array
    points: Array
    sigma_cm: Array
    sigma_delta_emp: Array  # rad
    sigma_delta_se: Array  # rad, standard error of the empirical std
    sigma_delta_69: Array  # rad, mean over trials of max(σ_E, σ_F) (6.9)/(6.10)
    sigma_delta_611: Array  # rad, (6.11) full-turn formula
    sigma_delta_612: Array  # rad, (6.12) with Stone's constants
    sigma_c_emp: Array  # cm
    sigma_c_se: Array  # cm
    sigma_c_613: Array  # cm, (6.13) with Stone's constants
    fit_612: tuple[float, float]  # our (a, b) of a X − b
    fit_613: tuple[float, float]
    trials: int
    radius_cm: float
    wall_s: float


def _circle_points(rng: np.random.Generator, x_deg: float, n: int, sigma: float, m: int) -> Array:
    """m noisy point sets (m, n, 3) on a circle of radius R about the origin in the XY plane."""
    t = np.deg2rad(np.linspace(0.0, x_deg, n))
    p = np.stack([RADIUS_CM * np.cos(t), RADIUS_CM * np.sin(t), np.zeros(n)], axis=-1)
    return p + sigma * rng.standard_normal((m, n, 3))


def _largest_std(e: Array) -> tuple[float, float]:
    """sqrt of the largest eigenvalue of the covariance of errors (m, 2), and its standard error."""
    cov = np.cov(e, rowvar=False)
    s = float(np.sqrt(np.linalg.eigvalsh(cov)[-1]))
    return s, s / np.sqrt(2.0 * (len(e) - 1))


def _fit_line(x_deg: Array, y: Array) -> tuple[float, float]:
    """Least-squares ``y ≈ a X − b``; returns (a, b)."""
    a, c = np.polyfit(x_deg, y, 1)
    return float(a), float(-c)


def run_features(
    seed: int = 0, trials: int = TRIALS, progress: TextIO | None = sys.stderr
) -> FeatureStudyResult:
    """Run every (X, N, σ) configuration; deterministic for a seed."""
    t0 = time.perf_counter()
    configs = [(x, n, s) for x in SWEEPS_DEG for n in POINTS for s in SIGMAS_CM]
    bar = Progress("features", len(configs), progress)
    rows: dict[str, list[float]] = {k: [] for k in ("d", "dse", "d69", "c", "cse")}
    for k, (x, n, s) in enumerate(configs):
        rng = np.random.default_rng(
            np.random.SeedSequence(seed, spawn_key=(zlib.crc32(b"features"), k))
        )
        tilt, center, d69 = [], [], []
        for a in range(0, trials, CHUNK):
            p = _circle_points(rng, x, n, s, min(CHUNK, trials - a))
            plane = fit_plane_lsq(p)
            circle = fit_circle(p, plane)
            tilt.append(plane.normal[:, :2])  # true normal +Z: in-plane components = tilt
            center.append(circle.center[:, :2])  # true center at the origin
            d69.append(revolute_accuracy(p, plane, circle).sigma_delta)
        rows["d"].append(0.0)
        rows["d"][-1], se = _largest_std(np.concatenate(tilt))
        rows["dse"].append(se)
        rows["c"].append(0.0)
        rows["c"][-1], se = _largest_std(np.concatenate(center))
        rows["cse"].append(se)
        rows["d69"].append(float(np.mean(np.concatenate(d69))))
        bar.step()
    cfg = np.array(configs, float)  # (C, 3): X, N, σ
    xs, ns, ss = cfg[:, 0], cfg[:, 1], cfg[:, 2]
    d, c = np.array(rows["d"]), np.array(rows["c"])
    sweep = np.deg2rad(xs)
    return FeatureStudyResult(
        sweep_deg=xs,
        points=ns,
        sigma_cm=ss,
        sigma_delta_emp=d,
        sigma_delta_se=np.array(rows["dse"]),
        sigma_delta_69=np.array(rows["d69"]),
        sigma_delta_611=sigma_delta_full(ss, RADIUS_CM, ns),
        sigma_delta_612=sigma_delta_partial(ss, RADIUS_CM, ns, sweep),
        sigma_c_emp=c,
        sigma_c_se=np.array(rows["cse"]),
        sigma_c_613=sigma_center(ss, ns, sweep),
        fit_612=_fit_line(xs, ss**2 / (RADIUS_CM**2 * ns * d**2)),
        fit_613=_fit_line(xs, ss**2 / (ns * c**2)),
        trials=trials,
        radius_cm=RADIUS_CM,
        wall_s=time.perf_counter() - t0,
    )
