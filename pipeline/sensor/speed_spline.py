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
#: The coarsest knot spacing of a spline chosen from the data (s): follows drifts with
#: periods of 15 min and more ((B-2)) to well under the rods' noise.
COARSEST_S = 120.0
#: The finest (s): knots are halved while they are further apart than this (three halvings
#: of :data:`COARSEST_S`, 8-15 s). A noiseless session in a speed of sound drifting with an
#: 8-minute period identified to 6.4e-9 cm at 15 s, 2.9e-7 cm at 30 s and 2.8e-4 cm at
#: 120 s (``--air drifting``, seed 3, 12 points); a knot interval still holds ~30 cycles.
FINEST_S = 15.0
#: The standard normal quantile of each halving's test (0.1 % one-sided): a session whose
#: air the coarser spline follows keeps it 999 times in 1,000 at each halving.
_Z = 3.09


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
        return cls.intervals(t_min, t_max, max(1, int(np.ceil(span / spacing_s))))

    @classmethod
    def intervals(cls, t_min: float, t_max: float, n_int: int) -> TimeSpline:
        """``n_int`` uniform knot intervals covering ``[t_min, t_max]``."""
        step = max(t_max - t_min, 1e-9) / n_int
        return cls(t_min + step * np.arange(-DEGREE, n_int + DEGREE + 1, dtype=float))

    @classmethod
    def chosen(
        cls,
        t_min: float,
        t_max: float,
        t_s: npt.ArrayLike,
        values: npt.ArrayLike,
        coarsest_s: float = COARSEST_S,
        finest_s: float = FINEST_S,
    ) -> TimeSpline:
        """The spline over ``[t_min, t_max]`` whose knots the samples ``values`` at
        ``t_s`` ask for: knots at most ``coarsest_s`` apart, halved while the finer spline
        fits the samples significantly better, until they are ``finest_s`` apart or less.

        Each halving is a nested model (the finer uniform knots hold the coarser), tested
        by the F statistic of the two least-squares fits, ``F = (ΔRSS/Δp) / (RSS/(n −
        p))``, against its 0.1 % quantile (:data:`_Z`, Wilson-Hilferty's χ² quantile; the
        samples are thousands of cycles). Scale-free: noisy samples of a slow drift keep
        ``coarsest_s``; samples of a drift the coarse spline cannot follow (or exact ones,
        noiseless) refine to the spacing that drift needs.
        """
        t, v = np.asarray(t_s, float), np.asarray(values, float)
        span = max(t_max - t_min, 1e-9)
        n_int = max(1, int(np.ceil(span / coarsest_s)))
        spline = cls.intervals(t_min, t_max, n_int)
        rss, p = spline._rss(t, v)
        while span / n_int > finest_s:
            finer = cls.intervals(t_min, t_max, 2 * n_int)
            rss2, p2 = finer._rss(t, v)
            dp, dof = p2 - p, len(t) - p2
            if dp <= 0 or dof <= 0:
                break
            d = float(dp)
            chi2_q = d * (1.0 - 2.0 / (9.0 * d) + _Z * np.sqrt(2.0 / (9.0 * d))) ** 3
            if not (rss - rss2) * dof > chi2_q * rss2:  # F > F_q; exact fits (RSS 0) refine
                break
            spline, rss, p, n_int = finer, rss2, p2, 2 * n_int
        return spline

    @property
    def spacing_s(self) -> float:
        """Time between two knots (s)."""
        return float(self.knots[1] - self.knots[0])

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

    def _rss(self, t_s: Array, values: Array) -> tuple[float, int]:
        """Residual sum of squares of :meth:`fit` and the rank of its normal equations."""
        coef, BtB = self._fit(t_s, values)
        idx, val = self.basis(t_s)
        r = values - np.einsum("ij,ij->i", val, coef[idx])
        return float(r @ r), int(np.linalg.matrix_rank(BtB))

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
        return self._fit(t_s, values)[0]

    def _fit(self, t_s: npt.ArrayLike, values: npt.ArrayLike) -> tuple[Array, Array]:
        """:meth:`fit`'s coefficients and its normal-equations matrix ``BᵀB``."""
        v = np.asarray(values, float)
        mean = float(np.mean(v))
        idx, val = self.basis(t_s)
        n = self.n_coef
        pairs = (idx[:, :, None] * n + idx[:, None, :]).ravel()
        BtB = np.bincount(pairs, (val[:, :, None] * val[:, None, :]).ravel(), n * n)
        Btv = np.bincount(idx.ravel(), (val * (v - mean)[:, None]).ravel(), n)
        coef, *_ = np.linalg.lstsq(BtB.reshape(n, n), Btv, rcond=None)
        return np.asarray(coef + mean, float), np.asarray(BtB.reshape(n, n), float)
