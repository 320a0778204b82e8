"""Rotations as rotation vectors: ``Exp``, ``Log`` and the right Jacobian of SO(3).

``Exp`` and ``Log`` are scipy's (``Rotation.from_rotvec`` / ``as_rotvec``). The right
Jacobian ``J_r(r)`` maps a change of the rotation vector to the body-frame rotation it
makes, ``Exp(r + δr) ≈ Exp(r) · Exp(J_r(r) δr)`` (Chirikjian, *Stochastic Models,
Information Theory, and Lie Groups* vol. 2, eq. 10.86; Sola et al., "A micro Lie theory",
eq. 143):

    ``J_r(r) = I − (1 − cos θ)/θ² [r]× + (θ − sin θ)/θ³ [r]×²``,  ``θ = |r|``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
#: Below this angle (rad) the series of J_r's coefficients is used: their closed forms
#: lose all digits to cancellation at θ ~ 1e-4 (θ² ~ 1e-8 of the 1 they are subtracted
#: from), the series' next term is θ⁴/720 ~ 1e-19 there.
_SERIES = 1e-4


def skew(v: npt.ArrayLike) -> Array:
    """``[v]×`` (..., 3, 3) of vectors (..., 3)."""
    v = np.asarray(v, float)
    S = np.zeros((*v.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    return S - np.swapaxes(S, -1, -2)


def rotation_from_vector(r: npt.ArrayLike) -> Array:
    """``Exp(r)``: rotation matrices (..., 3, 3) of rotation vectors (..., 3) (rad)."""
    from scipy.spatial.transform import Rotation

    r = np.asarray(r, float)
    return np.asarray(Rotation.from_rotvec(r.reshape(-1, 3)).as_matrix().reshape(*r.shape, 3))


def vector_from_rotation(R: npt.ArrayLike) -> Array:
    """``Log(R)``: rotation vectors (..., 3) (rad, |r| ≤ π) of rotation matrices (..., 3, 3)."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, float)
    return np.asarray(Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(*R.shape[:-1]))


def right_jacobian(r: npt.ArrayLike) -> Array:
    """``J_r(r)`` (3, 3) of one rotation vector ``r`` (3,) (module docstring)."""
    r = np.asarray(r, float)
    t = float(np.linalg.norm(r))
    if t < _SERIES:
        a, b = 0.5 - t * t / 24.0, 1.0 / 6.0 - t * t / 120.0
    else:
        a, b = (1.0 - np.cos(t)) / t**2, (t - np.sin(t)) / t**3
    K = skew(r)
    return np.asarray(np.eye(3) - a * K + b * K @ K)
