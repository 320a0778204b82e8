"""Air in the sensor volume: temperature linear in height, drifting slowly in time.

Appendix E models the lab as (B-3) temperature linear in height, (B-4) less than
2 °F from top to bottom of the active volume, (B-5) mean between 65 and 75 °F,
and (B-2) changes with time constants of minutes. The speed of sound follows
``c = 331.3 · sqrt(1 + T/273.15)`` m/s (ERRATA.md), which is *not* linear in
height; the simulator therefore integrates the time of flight numerically
(Gauss-Legendre, exact to rounding for this smooth integrand) rather than using
the linear-speed law the compensation assumes.
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

    def time_of_flight_s(
        self, src: np.ndarray, dst: np.ndarray, up: np.ndarray, t_s: np.ndarray
    ) -> np.ndarray:
        """Time for sound to travel the straight line ``src`` → ``dst``.

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
        if self.gradient_f_per_cm == 0.0 and self.drift_f == 0.0:
            # Uniform still air: every node has the same speed, so the quadrature
            # below reduces to one scalar factor (bit for bit the same sum).
            h = np.full(_NODES.shape, self.h_ref_cm)
            c0 = speed_of_sound_cm_s(self.temperature_f(h, np.zeros(())))
            return length * 0.5 * np.sum(_WEIGHTS / c0)
        h0, h1 = src @ up, dst @ up
        u = 0.5 * (_NODES + 1.0)  # nodes mapped to [0, 1]
        h = h0[..., None] + (h1 - h0)[..., None] * u
        c = speed_of_sound_cm_s(self.temperature_f(h, np.asarray(t_s, float)[..., None]))
        return length * 0.5 * np.sum(_WEIGHTS / c, axis=-1)


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
