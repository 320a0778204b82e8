"""The GP-8-3D sonic digitizer as the simulator plays it (Section 6.3, Appendix E).

One digitize cycle sparks sparkers 1-5 and reports a 5 × 4 array of slant
ranges (sparker × microphone A-D). A reported range is the internal nominal
speed of sound times the true time of flight (integrated through the
:class:`~pipeline.rig.atmosphere.Atmosphere`), plus noise (7.9)
(:mod:`pipeline.sensor.noise`) times a noise factor, quantized to the 0.01 cm
resolution. There is no echo (NaN) outside 30-250 cm or from behind the wall, and
no reported range outside that window (the digitizer gates its reports).

Fault switches, all off by default: a per-microphone range bias (acoustic-zero
offset), echo drop-outs, spurious outliers. A microphone position calibration
error (W_AC misalignment, Section 7.3) is not a property of the digitizer but
of the geometry the session records; see :mod:`pipeline.rig.simulate`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.rig.atmosphere import Atmosphere, DriftingLinearAir
from pipeline.sensor.geometry import DigitizerGeometry
from pipeline.sensor.noise import range_noise_sigma_cm


@dataclass(frozen=True)
class DigitizerModel:
    """Error model of the digitizer.

    Attributes
    ----------
    geometry : DigitizerGeometry
        The *actual* microphone and rod-sparker positions.
    noise_factor : float
        Multiplies (7.9); 0 turns range noise off.
    quantize : bool
        Round reported ranges to ``geometry.resolution_cm``.
    mic_bias_cm : tuple of 4 floats
        Acoustic-zero offset added to every range of microphone A, B, C, D.
    dropout_prob : float
        Probability that an echo is missed (NaN).
    outlier_prob : float
        Probability that a range is replaced by a spurious one (5-50 cm off).
    """

    geometry: DigitizerGeometry
    noise_factor: float = 1.0
    quantize: bool = True
    mic_bias_cm: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    dropout_prob: float = 0.0
    outlier_prob: float = 0.0


def sparker_positions(geometry: DigitizerGeometry, target_cm: np.ndarray) -> np.ndarray:
    """Sparkers 1-4 (rods) and 5 (target) for each cycle, shape (M, 5, 3)."""
    target = np.asarray(target_cm, float)
    rods = np.broadcast_to(geometry.rod_sparkers, (*target.shape[:-1], 4, 3))
    return np.concatenate([rods, target[..., None, :]], axis=-2)


def digitize(
    model: DigitizerModel,
    atmosphere: Atmosphere | DriftingLinearAir,
    target_cm: np.ndarray,
    t_s: np.ndarray,
    rng: np.random.Generator,
    standard_normal: np.ndarray | None = None,
) -> np.ndarray:
    """Raw slant ranges of many digitize cycles.

    Parameters
    ----------
    target_cm : ndarray, shape (M, 3)
        Target sparker (5) position per cycle, sensor frame.
    t_s : ndarray, shape (M,)
        Time of each cycle.
    standard_normal : ndarray, shape (M, 5, 4), optional
        Standard normal deviates of the range noise; drawn from ``rng`` when
        omitted. The Monte-Carlo study passes each robot's own stream here, so
        its results do not depend on how robots are batched.

    Returns
    -------
    raw : ndarray, shape (M, 5, 4)
        Reported ranges in cm (sparker 1-5 × microphone A-D); NaN = no echo.
    """
    g = model.geometry
    mics = g.microphones  # (4, 3)
    target = np.asarray(target_cm, float)
    t = np.asarray(t_s, float)
    # Rods (sparkers 1-4) and target (5) apart: the rods do not move, so in still air
    # their flight times are computed once, not once per cycle (same numbers).
    rods = g.rod_sparkers[:, None, :]  # (4, 1, 3)
    tof_rods = atmosphere.time_of_flight_s(rods, mics, g.up, t[:, None, None])
    tof_target = atmosphere.time_of_flight_s(target[:, None, :], mics, g.up, t[:, None])
    m = len(target)
    tof = np.concatenate(
        [np.broadcast_to(tof_rods, (m, 4, 4)), tof_target[:, None, :]], axis=1
    )  # (M, 5, 4)
    raw = g.nominal_speed_cm_s * tof + np.asarray(model.mic_bias_cm)
    sigma = model.noise_factor * range_noise_sigma_cm(raw)  # Eq. (7.9)
    z = rng.standard_normal(raw.shape) if standard_normal is None else standard_normal
    raw = raw + sigma * z
    if model.outlier_prob > 0:
        hit = rng.random(raw.shape) < model.outlier_prob
        jump = rng.uniform(5.0, 50.0, raw.shape) * rng.choice([-1.0, 1.0], raw.shape)
        raw = np.where(hit, raw + jump, raw)
    if model.quantize:
        raw = np.round(raw / g.resolution_cm) * g.resolution_cm
    dist_rods = np.linalg.norm(rods - mics, axis=-1)  # (4, 4)
    dist_target = np.linalg.norm(target[:, None, :] - mics, axis=-1)  # (M, 4)
    true_dist = np.concatenate(
        [np.broadcast_to(dist_rods, (m, 4, 4)), dist_target[:, None, :]], axis=1
    )
    sparks = sparker_positions(g, target)  # (M, 5, 3)
    heard = (
        (true_dist >= g.range_min_cm)
        & (true_dist <= g.range_max_cm)
        & (sparks[:, :, None, 2] > 0.0)  # a sparker behind the wall is never heard
        # The digitizer gates what it reports: never a range outside its window
        # (noise, a bias or a spurious echo can carry a heard one across).
        & (raw >= g.range_min_cm)
        & (raw <= g.range_max_cm)
    )
    if model.dropout_prob > 0:
        heard &= rng.random(raw.shape) >= model.dropout_prob
    return np.where(heard, raw, np.nan)
