"""Best-fit constant base and tool alignment between two kinematic models.

Finds ``X``, ``Y`` minimising ``Σ |X · T_model(q) · Y − T_ref(q)|`` over sampled
configurations. Used to express the design model in the signature's frame
(Section 5.3: both models must share one physical base frame) and, in the
audit, to compare models whose base and tool frames are conventions.
"""

from __future__ import annotations

from collections.abc import Callable

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
#: Directions of the 12 alignment parameters whose singular value is below this
#: fraction of the largest are symmetries of the model, not information: a SCARA's
#: design model commutes with a shift and a turn along its parallel axes, which the
#: base and the tool can share in any split (measured: 1.7e-12 of the largest, i.e.
#: round-off). Genuinely observable directions are far above it (Puma 560: 5.5e-3).
GAUGE_RCOND = 1e-8
#: Central-difference step for the Jacobian at the start (cm and rad): the residual
#: is smooth and of order 1-100, so 1e-6 keeps truncation and round-off near 1e-10.
JACOBIAN_STEP = 1e-6


#: A registration needs points spread in at least two directions: the second singular
#: value of the centred points above this fraction of the first (else the rotation
#: about their line is free and the fit would invent it).
MIN_SPREAD = 1e-6


def register_rigid(model: np.ndarray, measured: np.ndarray) -> np.ndarray | None:
    """The rigid transform (4, 4) best mapping ``model`` (m, 3) onto ``measured`` (m, 3),
    least squares (centroids matched, rotation by SVD (Kabsch), no scale); None when the
    points do not fix a rotation (fewer than 3, collinear)."""
    if len(model) < 3:
        return None
    cm, cp = model.mean(axis=0), measured.mean(axis=0)
    s = np.linalg.svd(model - cm, compute_uv=False)
    if not s[1] > MIN_SPREAD * max(s[0], 1e-300):
        return None
    # Kabsch: R = V diag(1, 1, ±1) Uᵀ of the SVD U Σ Vᵀ of Σ (a − ā)(b − b̄)ᵀ, the sign
    # making R a rotation (scipy's Rotation.align_vectors solves the same problem; its
    # import cost 0.09 s of CPU in a cold identify's design start, issue 45).
    U, _, Vt = np.linalg.svd((model - cm).T @ (measured - cp))
    d = 1.0 if np.linalg.det(Vt.T @ U.T) >= 0.0 else -1.0
    T = np.eye(4)
    T[:3, :3] = (Vt.T * [1.0, 1.0, d]) @ U.T
    T[:3, 3] = cp - T[:3, :3] @ cm
    return T


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

    Notes
    -----
    Where the model has a symmetry (a motion of the base that a motion of the
    tool undoes, for every q: a SCARA's shift and turn along its axes), X and
    Y are not unique. The fit then moves only in the parameter directions the
    data determine (:data:`GAUGE_RCOND`), so those shared motions stay where
    the start puts them: the models coincide at the first configuration, and
    the tool transform ``Y`` takes no share of a symmetry. Without this, the
    solver drifts along the symmetry (1,400 cm seen), a base and tool that fit
    just as well but put a pose given for the design tool far from its place.
    """
    Tr = np.asarray(T_ref, float)
    Tm = np.asarray(T_model, float)
    X0 = Tr[0] @ invert_transform(Tm[0])
    lever = np.diag([LEVER_CM, LEVER_CM, LEVER_CM, 1.0])

    def residual(x: Array) -> Array:
        T = X0 @ _pose(x[:6]) @ Tm @ _pose(x[6:])
        r: Array = ((T - Tr)[:, :3, :] @ lever).ravel()
        return r

    # The optimiser's Levenberg-Marquardt (numpy only): scipy.optimize's import cost
    # ~0.1-0.4 s of CPU in every identify for a fit of 12 parameters.
    from pipeline.optim.lm import dense_least_squares

    V = _observable_directions(residual)  # (12, k)
    # Tolerance at 1e-15: the noiseless audit must see 1e-13 cm agreement.
    fit = dense_least_squares(lambda z: residual(V @ z),
                              lambda z: _jacobian(residual, V @ z) @ V,
                              np.zeros(V.shape[1]), tol=1e-15)  # fmt: skip
    x = V @ fit.x
    return X0 @ _pose(x[:6]), _pose(x[6:])


def _observable_directions(residual: Callable[[Array], Array]) -> Array:
    """Orthonormal basis (12, k) of the parameter directions the residual determines
    at the start x = 0: right singular vectors above :data:`GAUGE_RCOND`."""
    _, s, Vt = np.linalg.svd(_jacobian(residual, np.zeros(12)), full_matrices=False)
    keep = s > GAUGE_RCOND * s[0]
    if keep.all():  # no symmetry: the parameters as they are
        return np.eye(12)
    out: Array = Vt[keep].T
    return out


def _jacobian(residual: Callable[[Array], Array], x: Array) -> Array:
    """``∂residual/∂x`` (R, 12) at ``x`` by central differences (:data:`JACOBIAN_STEP`)."""
    h = JACOBIAN_STEP
    return np.stack(
        [(residual(x + h * e) - residual(x - h * e)) / (2.0 * h) for e in np.eye(12)], axis=1
    )
