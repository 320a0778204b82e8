"""The measurement block of target positions: three whitened residuals per position.

``r = L⁻¹ (p − m)`` with ``Σ = L Lᵀ`` the position's covariance (Cholesky), ``m`` the
measured position, ``p`` the chain's prediction; ``∂r/∂p = L⁻¹``. Σ per row, from the
``positions`` table:

- point sensors: the recorded ``cov_*_cm2`` (full 3×3), else ``sigma_cm``² · I;
- sonic positions (triangulated from microphones A, B, C; ``refine.level=points``, the
  range level being the sonic default): the mean of ``n_used`` cycles (one or more) of a
  trilateration, so
  ``Σ = U⁻¹ diag(σ_A², σ_B², σ_C²) U⁻ᵀ / n_used`` with ``U`` the unit vectors from the
  microphones to the position (``∂range/∂p``) and ``σ`` the range noise (7.9) with its
  0.01 cm rounding (:func:`pipeline.sensor.noise.range_sigma_cm`). Anisotropic: depth
  across the microphone plane is several times worse than along it. The isotropic
  ``scatter_cm² / n_used`` (floored at resolution²/12) of notes/common15.md made
  robot3's refined audit 1.7× WORSE than the thesis (0.0156 vs 0.0093 cm), this law
  1.16× better (0.0080 cm): the scatter of 10 cycles is a noisy weight, and isotropic
  weights trust the depth as much as the plane. It is used only when no geometry is
  given (:data:`RESOLUTION_VAR_CM2` floor);
- every position (point sensors and sonic positions alike) adds the noise of the encoder
  readings it is predicted at, ``Σ_k g_k g_kᵀ · resolution_k² / 12`` with ``g_k = ∂p/∂q_k``
  (:func:`with_reading_noise`, built in :func:`pipeline.refine.problem.chain_problem`):
  tracker seeds 5, 7, 8 (20 points) moved from thesis/refined 0.84, 1.43, 0.88 to 0.88,
  1.44, 0.96 with it;
- a row with no stated noise takes the median variance of the rows that have one (1 cm²
  when none has: the covariance is scaled by the fitted noise χ²/dof anyway).

Rows without a position (null) are not in the block. Validation rows (sweep ``check``,
−1) are never in the block: held out for :mod:`pipeline.stages.validation` and the holdout
(the block of a ``positions`` table: :func:`pipeline.stages.refine_problem.point_block`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa

from pipeline.optim.block import Array, Linearization
from pipeline.sensor.geometry import DigitizerGeometry
from pipeline.sensor.noise import range_sigma_cm

#: Variance of a uniform rounding to the sonic digitizer's 0.01 cm resolution (cm²).
RESOLUTION_VAR_CM2 = 0.01**2 / 12.0


@dataclass(frozen=True)
class PositionRows:
    """Measured target positions and what their source states of their noise (the rows
    of a ``positions`` table: :func:`pipeline.stages.refine_problem.position_rows`).

    Attributes
    ----------
    p : ndarray, shape (m, 3)
        Positions (sensor frame, cm); NaN where none.
    cov : ndarray, shape (m, 3, 3)
        Recorded covariances (cm²); NaN where not all six entries are recorded.
    sigma_cm, scatter_cm : ndarray, shape (m,)
        Recorded isotropic σ (NaN where none); scatter of the averaged cycles (sonic).
    n_used, n_samples : ndarray, shape (m,)
        Cycles averaged (float) and recorded (int) per position.
    """

    p: Array
    cov: Array
    sigma_cm: Array
    scatter_cm: Array
    n_used: Array
    n_samples: np.ndarray


def trilateration_covariances(
    p: np.ndarray, geometry: DigitizerGeometry, n_used: np.ndarray
) -> np.ndarray:
    """Σ (m, 3, 3) of the means of ``n_used`` (m,) trilaterations at ``p`` (m, 3), cm²."""
    v = p[:, None, :] - geometry.microphones[None, :3]  # A, B, C -> the target
    ranges = np.linalg.norm(v, axis=2)
    U_inv = np.linalg.inv(v / ranges[..., None])  # ∂p/∂ranges
    var = range_sigma_cm(ranges, geometry.resolution_cm) ** 2
    return np.einsum("kij,kj,klj->kil", U_inv, var, U_inv) / n_used[:, None, None]


def position_covariances(rows: PositionRows, geometry: DigitizerGeometry | None = None) -> Array:
    """Σ (m, 3, 3) of measured positions, per the module docstring."""
    cov = rows.cov.copy()
    full = np.isfinite(cov).all(axis=(1, 2))
    var = rows.sigma_cm**2
    scatter = rows.scatter_cm
    n_used = rows.n_used
    # Positions without a stated noise: the mean of n_used cycles. With the digitizer's
    # geometry the range noise law gives their covariance, one cycle or many (before
    # issue 33 a single-cycle position took the 1 cm² fill: held-out expectations 1.7 cm
    # against 0.13 cm measured); without it only a scatter of two cycles or more does.
    has_law = rows.n_samples >= 1 if geometry is not None else rows.n_samples > 1
    sonic = np.isnan(var) & ~full & has_law
    with np.errstate(invalid="ignore", divide="ignore"):
        var = np.where(sonic, np.maximum(scatter**2 / n_used, RESOLUTION_VAR_CM2), var)
    if geometry is not None and sonic.any():
        at = sonic & (n_used > 0)
        var[at] = np.nan
        cov[at] = trilateration_covariances(rows.p[at], geometry, n_used[at])
    iso = ~full & np.isfinite(var)
    cov[iso] = var[iso, None, None] * np.eye(3)
    stated = np.isfinite(cov).all(axis=(1, 2))
    if not stated.all():
        fill = np.median(np.trace(cov[stated], axis1=1, axis2=2)) / 3 if stated.any() else 1.0
        cov[~stated] = fill * np.eye(3)
    return cov


@dataclass(eq=False)  # not frozen: MeasurementBlock declares settable attributes
class PointBlock:
    """A :class:`~pipeline.optim.block.MeasurementBlock` of measured target positions."""

    keys: pa.Table
    measured: Array  # (K, 3) cm
    whiten: Array  # (K, 3, 3) L⁻¹
    param_names: tuple[str, ...] = ()
    param_units: tuple[str, ...] = ()
    x0: Array = field(default_factory=lambda: np.zeros(0))

    def linearize(self, p: Array, x: Array) -> Linearization:
        K = len(self.measured)
        r = np.einsum("kij,kj->ki", self.whiten, p - self.measured)
        return Linearization(
            r=r.reshape(-1),
            pos=np.repeat(np.arange(K, dtype=np.int64), 3),
            d_p=self.whiten.reshape(3 * K, 3),
            d_x=np.zeros((3 * K, 0)),
        )


def with_reading_noise(block: PointBlock, tangents: Array, var_q: Array) -> PointBlock:
    """``block`` with the encoder readings' noise added to each position's covariance:
    ``Σ + Σ_k g_k g_kᵀ σ_k²`` (effective variance), ``g_k = ∂p/∂q_k`` (K, n, 3) at the start
    and ``σ_k²`` (n,) the variance of joint k's reading (its rounding, resolution²/12).
    A reading error moves a target along its circle; the thesis's circle fit ignores the
    readings and so this error, a fit through the readings must weigh it."""
    L = np.linalg.inv(block.whiten)
    cov = L @ np.swapaxes(L, 1, 2) + np.einsum("kni,knj,n->kij", tangents, tangents, var_q)
    return PointBlock(block.keys, block.measured, np.linalg.inv(np.linalg.cholesky(cov)))
