"""Best-fit constant base and tool alignment between two kinematic models.

Finds ``X``, ``Y`` minimising ``Σ |X · T_model(q) · Y − T_ref(q)|`` over sampled
configurations. Used to express the design model in the signature's frame
(Section 5.3: both models must share one physical base frame) and, in the
audit, to compare models whose base and tool frames are conventions.
"""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.transforms import (
    Array,
    ArrayLike,
    invert_transform,
    transform_from_xyz_rpy,
)

#: Orientation residuals are weighted as positions on a 10 cm lever: the scale of
#: a tool, so 1e-3 rad weighs like 0.01 cm.
LEVER_CM = 10.0


def _pose(x: Array) -> Array:
    return transform_from_xyz_rpy(x[:3], x[3:6])


def fit_alignment(T_ref: ArrayLike, T_model: ArrayLike) -> tuple[Array, Array]:
    """Constant ``X`` (base) and ``Y`` (tool) with ``T_ref ≈ X · T_model · Y``.

    Parameters
    ----------
    T_ref, T_model : array_like, shape (m, 4, 4)
        Poses of the two models at the same m configurations (m ≥ 3, spread out).

    Returns
    -------
    X, Y : ndarray, shape (4, 4)
    """
    Tr = np.asarray(T_ref, float)
    Tm = np.asarray(T_model, float)
    X0 = Tr[0] @ invert_transform(Tm[0])
    lever = np.diag([LEVER_CM, LEVER_CM, LEVER_CM, 1.0])

    def residual(x: Array) -> Array:
        T = X0 @ _pose(x[:6]) @ Tm @ _pose(x[6:])
        r: Array = ((T - Tr)[:, :3, :] @ lever).ravel()
        return r

    from scipy.optimize import least_squares  # lazy: 0.4 s of import, needed only here

    # Tolerances at 1e-15: the noiseless audit must see 1e-13 cm agreement.
    fit = least_squares(residual, np.zeros(12), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return X0 @ _pose(fit.x[:6]), _pose(fit.x[6:])
