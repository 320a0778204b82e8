"""The sonic digitizer's range noise: the sensor spec (7.9) plus its quantization.

A reported slant range ``X`` (cm) carries Gaussian noise of standard deviation
``σ = 9.6432e-5·X + 0.003`` cm (Eq. (7.9), ERRATA.md) and is then rounded to the
digitizer's resolution (0.01 cm, Section 6.3.1). Rounding adds a uniform error of
variance ``resolution²/12``, independent of the noise. The simulator draws the
noise from :func:`range_noise_sigma_cm`; the range-level refinement weighs each
range by :func:`range_sigma_cm`.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

NOISE_SLOPE = 9.6432e-5  # Eq. (7.9): σ = 9.6432e-5 · X + 0.003 (cm)
NOISE_FLOOR_CM = 0.003  # Eq. (7.9)


def range_noise_sigma_cm(s_cm: npt.ArrayLike) -> Array:
    """Standard deviation (cm) of the noise of slant ranges ``s_cm`` (cm), Eq. (7.9); shape (...)
    of ``s_cm``."""
    return np.asarray(NOISE_SLOPE * np.asarray(s_cm, float) + NOISE_FLOOR_CM, float)  # Eq. (7.9)


def range_sigma_cm(s_cm: npt.ArrayLike, resolution_cm: float) -> Array:
    """Standard deviation (cm) of reported ranges: (7.9) and the rounding to ``resolution_cm``.

    Parameters
    ----------
    s_cm : array_like, shape (...)
        Slant ranges (cm).
    resolution_cm : float
        Quantization step of the reports (0 for unrounded ranges).

    Returns
    -------
    sigma : ndarray, shape (...)
        ``sqrt(σ₇.₉² + resolution²/12)``.
    """
    return np.asarray(np.hypot(range_noise_sigma_cm(s_cm), resolution_cm / np.sqrt(12.0)), float)
