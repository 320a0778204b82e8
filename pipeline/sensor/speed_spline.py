"""The speed of sound's slow drift in time: a cubic B-spline ``a(t)``.

The range model (:mod:`pipeline.sensor.range_model`) carries the speed ratio
``f(h, t) = a(t) + g·(h − h_ref)``. ``a`` drifts with time constants of minutes
(Appendix E, (B-2)); a cubic B-spline with uniform knots a couple of minutes apart
follows such a drift and stays linear in its coefficients.

The basis is evaluated here with FITPACK's recurrence (``fpbspl``, the one behind
``scipy.interpolate.BSpline.design_matrix``), vectorised in numpy: the same bits as
scipy's (``tests/test_speed_spline.py``) without importing ``scipy.interpolate`` (~0.03 s
of a cold ``pipeline identify`` beyond the scipy.optimize that the design alignment
imports anyway; ~0.17 s with it, issue 18).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

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

    def basis(self, t_s: npt.ArrayLike) -> tuple[npt.NDArray[np.int64], Array]:
        """The ``DEGREE + 1`` basis functions not zero at each time (clipped to the span):
        their indices and values, each shape (M, DEGREE + 1);
        ``design(t)[i, idx[i]] == val[i]``."""
        t_knots, k = self.knots, DEGREE
        n = len(t_knots) - k - 1
        lo, hi = t_knots[k], t_knots[n]
        x = np.clip(np.atleast_1d(np.asarray(t_s, float)), lo, hi)
        # knot interval l: t[l] <= x < t[l + 1], k <= l < n (x = t[n]: the last interval)
        ell = np.clip(np.searchsorted(t_knots, x, side="right") - 1, k, n - 1)
        h = np.zeros((len(x), k + 1))
        h[:, 0] = 1.0
        for j in range(1, k + 1):  # Cox-de Boor, in fpbspl's order of operations
            hh = h[:, :j].copy()
            h[:, 0] = 0.0
            for i in range(1, j + 1):
                right, left = t_knots[ell + i], t_knots[ell + i - j]  # distinct: uniform knots
                f = hh[:, i - 1] / (right - left)
                h[:, i - 1] += f * (right - x)
                h[:, i] = f * (x - left)
        idx = (ell - k)[:, None] + np.arange(k + 1)
        return idx.astype(np.int64), h

    def design(self, t_s: npt.ArrayLike) -> Array:
        """Basis values at times ``t_s`` (M,), clipped to the span, dense shape (M, n_coef)."""
        idx, val = self.basis(t_s)
        out = np.zeros((len(idx), self.n_coef))
        np.put_along_axis(out, idx, val, axis=1)
        return out

    def fit(self, t_s: npt.ArrayLike, values: npt.ArrayLike) -> Array:
        """Least-squares coefficients (n_coef,) through ``values`` at ``t_s``.

        A coefficient no sample touches keeps the mean of the values (the minimum-norm
        solution about that mean). Solved on the normal equations ``BᵀB c = Bᵀv``, built
        from the four basis functions of each sample: linear in the samples. ``lstsq`` of
        the dense (samples × n_coef) ``B``, both growing with the session's length, took
        2.3 s at 1,600 points per sweep. The minimum-norm solution of the normal
        equations is ``B⁺v`` itself; ``cond(BᵀB)`` of the uniform cubic basis is ~2e3,
        so squaring the condition costs ~3 of 16 digits (1e-14 from ``lstsq``, tested).
        """
        v = np.asarray(values, float)
        mean = float(np.mean(v))
        idx, val = self.basis(t_s)
        n = self.n_coef
        pairs = (idx[:, :, None] * n + idx[:, None, :]).ravel()
        BtB = np.bincount(pairs, (val[:, :, None] * val[:, None, :]).ravel(), n * n)
        Btv = np.bincount(idx.ravel(), (val * (v - mean)[:, None]).ravel(), n)
        coef, *_ = np.linalg.lstsq(BtB.reshape(n, n), Btv, rcond=None)
        return np.asarray(coef + mean, float)
