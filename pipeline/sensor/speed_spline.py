"""The speed of sound's slow drift in time: a cubic B-spline ``a(t)``.

The range model (:mod:`pipeline.sensor.range_model`) carries the speed ratio
``f(h, t) = a(t) + g·(h − h_ref)``. ``a`` drifts with time constants of minutes
(Appendix E, (B-2)); a cubic B-spline with uniform knots a couple of minutes apart
follows such a drift and stays linear in its coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.interpolate import BSpline

Array = npt.NDArray[np.float64]

DEGREE = 3  # cubic: a smooth drift, continuous second derivative


@dataclass(frozen=True)
class TimeSpline:
    """Uniform cubic B-spline basis over a time span.

    Attributes
    ----------
    knots : ndarray, shape (n_coef + 4,)
        Full knot vector (s); the interior covers ``[t_min, t_max]``.
    """

    knots: Array

    @classmethod
    def over(cls, t_min: float, t_max: float, spacing_s: float) -> TimeSpline:
        """Knots at most ``spacing_s`` apart covering ``[t_min, t_max]`` (one interval at least)."""
        span = max(t_max - t_min, 1e-9)  # one cycle only: a constant a(t) on a tiny interval
        n_int = max(1, int(np.ceil(span / spacing_s)))
        step = span / n_int
        return cls(t_min + step * np.arange(-DEGREE, n_int + DEGREE + 1, dtype=float))

    @property
    def n_coef(self) -> int:
        return len(self.knots) - DEGREE - 1

    @property
    def centres_s(self) -> Array:
        """The time at which each coefficient's basis function peaks, shape (n_coef,)."""
        return np.asarray(self.knots[2 : 2 + self.n_coef], float)

    def _matrix(self, t_s: npt.ArrayLike):  # -> scipy.sparse.csr_array
        lo, hi = self.knots[DEGREE], self.knots[-DEGREE - 1]
        t = np.clip(np.atleast_1d(np.asarray(t_s, float)), lo, hi)
        return BSpline.design_matrix(t, self.knots, DEGREE)

    def design(self, t_s: npt.ArrayLike) -> Array:
        """Basis values at times ``t_s`` (M,), clipped to the span, dense shape (M, n_coef)."""
        return np.asarray(self._matrix(t_s).toarray(), float)

    def basis(self, t_s: npt.ArrayLike) -> tuple[npt.NDArray[np.int64], Array]:
        """The ``DEGREE + 1`` basis functions not zero at each time: their indices and
        values, each shape (M, DEGREE + 1); ``design(t)[i, idx[i]] == val[i]``."""
        m = self._matrix(t_s)
        k = DEGREE + 1
        return m.indices.astype(np.int64).reshape(-1, k), np.asarray(m.data, float).reshape(-1, k)

    def fit(self, t_s: npt.ArrayLike, values: npt.ArrayLike) -> Array:
        """Least-squares coefficients (n_coef,) through ``values`` at ``t_s``.

        A coefficient no sample touches keeps the mean of the values (the minimum-norm
        solution about that mean).
        """
        v = np.asarray(values, float)
        mean = float(np.mean(v))
        coef, *_ = np.linalg.lstsq(self.design(t_s), v - mean, rcond=None)
        return np.asarray(coef + mean, float)
