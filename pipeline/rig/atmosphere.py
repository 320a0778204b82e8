"""Air in the sensor volume: temperature linear in height, drifting slowly in time.

Appendix E models the lab as (B-3) temperature linear in height, (B-4) less than
2 °F from top to bottom of the active volume, (B-5) mean between 65 and 75 °F,
and (B-2) changes with time constants of minutes. The speed of sound follows
``c = 331.3 · sqrt(1 + T/273.15)`` m/s (ERRATA.md), which is *not* linear in
height; the simulator therefore integrates the time of flight numerically
(Gauss-Legendre, exact to rounding for this smooth integrand) rather than using
the linear-speed law the compensation assumes.

:class:`DriftingLinearAir` is Appendix E's model itself: a speed of sound exactly linear in
height whose mean drifts as a sum of sinusoids (periods of minutes, (B-2)). The range
model fits exactly that law, so a noiseless session in it must identify exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.sensor.geometry import speed_of_sound_cm_s

#: 16 Gauss-Legendre nodes: the integrand 1/c(T(s)) varies by < 0.2 % along a ray and
#: is analytic, so the quadrature error is far below double rounding.
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(16)


@dataclass(frozen=True)
class Atmosphere:
    """Temperature field ``T(h, t) = mean(t) + gradient · (h − h_ref)``.

    Attributes
    ----------
    mean_f : float
        Mean temperature at ``h_ref`` (°F), (B-5).
    gradient_f_per_cm : float
        Vertical gradient (°F per cm); (B-4) bounds it by 2 °F over the volume.
    drift_f : float
        Amplitude of the slow sinusoidal drift of the mean (°F), (B-2).
    drift_period_s : float
        Period of that drift (s).
    drift_phase : float
        Phase of the drift (rad).
    h_ref_cm : float
        Height (above microphone C) where ``mean_f`` applies.
    """

    mean_f: float = 70.0
    gradient_f_per_cm: float = 0.0
    drift_f: float = 0.0
    drift_period_s: float = 1200.0
    drift_phase: float = 0.0
    h_ref_cm: float = 0.0

    def temperature_f(self, h_cm: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        """Temperature (°F) at heights ``h_cm`` and times ``t_s`` (broadcast)."""
        mean = self.mean_f + self.drift_f * np.sin(
            2.0 * np.pi * np.asarray(t_s, float) / self.drift_period_s + self.drift_phase
        )
        return mean + self.gradient_f_per_cm * (np.asarray(h_cm, float) - self.h_ref_cm)

    def speed_cm_s(self, h_cm: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        """Speed of sound (cm/s) at heights ``h_cm`` and times ``t_s`` (broadcast)."""
        return speed_of_sound_cm_s(self.temperature_f(h_cm, t_s))

    @property
    def still(self) -> bool:
        """Uniform air that does not drift."""
        return self.gradient_f_per_cm == 0.0 and self.drift_f == 0.0

    def time_of_flight_s(
        self, src: np.ndarray, dst: np.ndarray, up: np.ndarray, t_s: np.ndarray
    ) -> np.ndarray:
        """Time for sound to travel the straight line ``src`` → ``dst``
        (:func:`time_of_flight_s`)."""
        return time_of_flight_s(self, src, dst, up, t_s)


def time_of_flight_s(
    air: Atmosphere | DriftingLinearAir,
    src: np.ndarray,
    dst: np.ndarray,
    up: np.ndarray,
    t_s: np.ndarray,
) -> np.ndarray:
    """Time for sound to travel the straight line ``src`` → ``dst`` through ``air``.

    Parameters
    ----------
    src, dst : ndarray, shape (..., 3)
        End points in the sensor frame (cm), broadcast against each other.
    up : ndarray, shape (3,)
        Vertical unit vector in the sensor frame.
    t_s : ndarray, shape (...)
        Time of the spark (the field is frozen during the ~10 ms flight).

    Returns
    -------
    tof : ndarray, shape (...)
        Seconds: ``∫ ds / c(T(h(s)))`` along the segment.
    """
    src = np.asarray(src, float)
    dst = np.asarray(dst, float)
    length = np.linalg.norm(dst - src, axis=-1)
    if air.still:
        # Uniform still air: every node has the same speed, so the quadrature
        # below reduces to one scalar factor (bit for bit the same sum).
        h = np.full(_NODES.shape, air.h_ref_cm)
        c0 = air.speed_cm_s(h, np.zeros(()))
        return length * 0.5 * np.sum(_WEIGHTS / c0)
    h0, h1 = src @ up, dst @ up
    u = 0.5 * (_NODES + 1.0)  # nodes mapped to [0, 1]
    h = h0[..., None] + (h1 - h0)[..., None] * u
    c = air.speed_cm_s(h, np.asarray(t_s, float)[..., None])
    return length * 0.5 * np.sum(_WEIGHTS / c, axis=-1)


@dataclass(frozen=True)
class DriftingLinearAir:
    """Speed of sound linear in height, its mean drifting in time (Appendix E's model)::

        c(h, t) = c_ref · (1 + Σ_k A_k sin(2π t / P_k + φ_k) + g · (h − h_ref))

    The time of flight along a line is then (E.2) exactly; :func:`time_of_flight_s`
    integrates it (16 Gauss-Legendre nodes, exact to rounding for ``1/c`` linear in the
    speed).

    Attributes
    ----------
    c_ref_cm_s : float
        Mean speed at ``h_ref`` (cm/s).
    gradient_per_cm : float
        ``g``: relative change of the speed per cm of height.
    drift : tuple of (amplitude, period_s, phase_rad)
        The sinusoids of the mean's relative drift.
    h_ref_cm : float
        Height (above microphone C) where ``c_ref_cm_s`` applies.
    """

    c_ref_cm_s: float
    gradient_per_cm: float
    drift: tuple[tuple[float, float, float], ...]
    h_ref_cm: float = 0.0
    kind: str = "drifting"  # rig-truth.json tells the two airs apart

    @property
    def still(self) -> bool:
        return self.gradient_per_cm == 0.0 and not self.drift

    def speed_cm_s(self, h_cm: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        """Speed of sound (cm/s) at heights ``h_cm`` and times ``t_s`` (broadcast)."""
        t = np.asarray(t_s, float)
        mean = np.zeros_like(t)
        for amplitude, period_s, phase in self.drift:
            mean = mean + amplitude * np.sin(2.0 * np.pi * t / period_s + phase)
        rel = mean + self.gradient_per_cm * (np.asarray(h_cm, float) - self.h_ref_cm)
        return self.c_ref_cm_s * (1.0 + rel)

    def time_of_flight_s(
        self, src: np.ndarray, dst: np.ndarray, up: np.ndarray, t_s: np.ndarray
    ) -> np.ndarray:
        """Time for sound to travel the straight line ``src`` → ``dst``
        (:func:`time_of_flight_s`)."""
        return time_of_flight_s(self, src, dst, up, t_s)


#: Periods of the drifting air's sinusoids (s): 8 to 45 minutes, the range issue 33 names.
DRIFT_PERIODS_S = (480.0, 1100.0, 2700.0)


def drifting_linear_air(rng: np.random.Generator, h_ref_cm: float) -> DriftingLinearAir:
    """A :class:`DriftingLinearAir` within (B-2)-(B-5): the speed at 66-74 °F, a gradient
    of 0.3-1.8 °F over 150 cm, and three drifts of ±0.05-0.3 °F with the periods of
    :data:`DRIFT_PERIODS_S` (each a relative amplitude: 1 °F is ~9.4e-4 of the speed)."""
    mean_f = float(rng.uniform(66.0, 74.0))
    c = float(speed_of_sound_cm_s(mean_f))
    per_f = float(speed_of_sound_cm_s(mean_f + 0.5) - speed_of_sound_cm_s(mean_f - 0.5)) / c
    gradient_f = float(rng.uniform(0.3, 1.8) / 150.0 * rng.choice([-1.0, 1.0]))
    drift = tuple(
        (float(rng.uniform(0.05, 0.3)) * per_f, p, float(rng.uniform(0.0, 2.0 * np.pi)))
        for p in DRIFT_PERIODS_S
    )
    return DriftingLinearAir(c, gradient_f * per_f, drift, h_ref_cm)


def random_atmosphere(rng: np.random.Generator, h_ref_cm: float) -> Atmosphere:
    """A lab within (B-2)-(B-5): mean 66-74 °F, 0.3-1.8 °F over 150 cm, ±0.3 °F drift."""
    return Atmosphere(
        mean_f=float(rng.uniform(66.0, 74.0)),
        gradient_f_per_cm=float(rng.uniform(0.3, 1.8) / 150.0 * rng.choice([-1.0, 1.0])),
        drift_f=float(rng.uniform(0.05, 0.3)),
        drift_period_s=float(rng.uniform(900.0, 2400.0)),
        drift_phase=float(rng.uniform(0.0, 2.0 * np.pi)),
        h_ref_cm=h_ref_cm,
    )
