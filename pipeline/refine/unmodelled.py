"""The unmodelled error: what a fitted model leaves in its residuals beyond the
measurements' noise (issue 41).

A real arm has error no kinematic model has (backlash, link bending, gear and bearing
errors, temperature): its fit residual is larger than the tracker's noise, χ²/dof 27 to
1,700 on five real laser-tracker sets. The parameters' covariance (scaled by χ²/dof) says
how well the model's own parameters are known; it does not say how far the arm will be
from where the model sends it, which also includes the error the model leaves out.

With the fit's 3-D residuals ``r_k = m_k − p̂_k`` at its ``K`` points, a model of ``P``
parameters and the refinement's ``χ²/dof = s²`` (its whitened residuals: the points'
stated noise and the joint readings' noise, as the fit weighs them), the residual's mean
square corrected for the fitted directions, ``ms = mean|r|² · 3K / (3K − P)``, is the
noise model's share ``ms / s²`` and the rest: an arm that departs from the model by an
error of RMS length ``u`` that behaves like noise across the poses gives

    ``u² = ms · (1 − 1 / s²)``

Whether there is any: the fit's ``χ²`` against ``χ²(dof)``, p-value below
:data:`SIGNIFICANCE` (a session of the model's own noise says "none" but once in a
thousand); without it ``u = 0`` and the prediction is the parameters' alone, as before
issue 41. (A sonic session's is not estimated, :mod:`pipeline.stages.uncertainty`.) Without a
stated noise (an import without σ: every point weighs 1 cm) nothing separates noise from
unmodelled error: the whole residual counts, ``u² = ms``, the conservative reading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.optim.block import Array

#: p-value of the χ² test below which the residual holds unmodelled error: 1e-3, the
#: non-geometric terms' former score test's level (a clean session is flagged once in a
#: thousand).
SIGNIFICANCE = 1e-3


@dataclass(frozen=True)
class Unmodelled:
    """The unmodelled error's RMS length ``rms_cm`` (0 when not significant), the fit's
    3-D residual RMS, the χ² test's p-value (None without a stated noise) and the points
    it was judged on."""

    rms_cm: float
    residual_rms_cm: float
    p_value: float | None
    points: int


def unmodelled_error(
    residuals: Array,
    n_params: int,
    chi2: float,
    dof: int,
    noise_stated: bool = True,
    components: int = 3,
) -> Unmodelled:
    """:class:`Unmodelled` of the 3-D fit residuals ``residuals`` (K, 3) cm of a model of
    ``n_params`` parameters whose fit had ``chi2`` on ``dof`` degrees of freedom
    (module docstring); ``noise_stated`` false: the points' noise is unknown. Rows with a
    NaN are left out. ``components``: the measured components per row (3; a camera's
    pixel residuals carried to the target: 2, their third component 0), the ``3K`` of
    the module docstring."""
    from scipy.special import chdtrc  # χ² survival function (scipy.stats imports ~0.3 s)

    r = np.asarray(residuals, float)
    r = r[np.isfinite(r).all(axis=1)]
    K = len(r)
    n = components * K
    if K == 0 or n <= n_params or dof <= 0:
        return Unmodelled(0.0, float("nan"), None, K)
    rms = float(np.sqrt(np.mean(np.sum(r**2, axis=1))))
    ms = rms**2 * n / (n - n_params)
    if not noise_stated:
        return Unmodelled(float(np.sqrt(ms)), rms, None, K)
    p = float(chdtrc(dof, chi2))
    s2 = chi2 / dof
    u2 = ms * (1.0 - 1.0 / s2) if p < SIGNIFICANCE else 0.0
    return Unmodelled(float(np.sqrt(max(u2, 0.0))), rms, p, K)
