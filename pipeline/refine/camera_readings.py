"""What the joint readings' noise adds to a camera fit's covariance (issue 39).

Each image is predicted at its encoder readings, which differ from where the joints were by
their rounding (``σ_k = resolution_k / √12``, as a point sensor's fit weighs it:
:mod:`pipeline.refine.points`). Unlike a point's, that error is shared by every point of
the image: one reading error moves the whole image (eye-in-hand, a wrist error of
``δθ`` turns the camera and shifts every pixel by ``f · δθ``: 0.025 px for the Puma's
0.005° encoder, against the 0.2 px of one point averaged over ~30 points of an image,
0.037 px). The fit weighs the pixels alone (per point, independent), so its Gauss-Newton
covariance misses that part; it is added as the sandwich of the least-squares estimate
under the readings' noise:

    ``Σ_q-part = H⁻¹ (Σ_i J_iᵀ G_i Σ_q G_iᵀ J_i) H⁻¹``

with ``H⁻¹`` the fit's unscaled covariance, ``J_i`` the whitened Jacobian of image ``i``'s
rows, ``G_i = ∂r_i/∂q_i`` their derivatives in that image's readings (central differences
of the predicted pixels, :data:`STEP`) and ``Σ_q = diag(σ_k²)``. Measured on five seeds per
row (``python -m bench.camera_spread``): without it the Puma eye-in-hand sessions' audited
errors were 1.8-2.9× their predicted variance along the predicted directions (mean z²),
the same sessions with the readings exact 1.1-1.3.

Real images share more than the readings' rounding: on industrial_calibration's two sets
25-50 % of the residuals' square was common to the points of an image (where independent
pixels put ~3 %: the robot's own pose error at each image, the lens's misfit over the
board's patch), and held-out images were 1.47-1.61× their prediction (docs/camera.md).
The same sandwich takes that error as a small rigid motion of the target in the camera
per image (:func:`pose_basis`, :func:`pose_covariance`), its variance estimated from the
fit's residuals along those motions and outside them, and counted only when it is
significant (:func:`image_pose_variance`): held out 0.99-1.22× the prediction.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.optim.block import Array
from pipeline.refine.camera_block import CameraBlock, _skew
from pipeline.refine.kinematics import ChainModel

#: Central-difference step of a joint reading (rad / cm): the pixels' error is ~h² times
#: their third derivative (~1e-12 px), their rounding ~1e-13 px / h = 1e-7 relative.
STEP = 1e-6


def encoder_sigma(resolution: Array, prismatic: Array) -> Array:
    """The joint readings' σ (n,) rad / cm of encoders of ``resolution`` (n, boundary
    units): their rounding, resolution / √12."""
    from pipeline.units import joints_to_internal

    return np.asarray(joints_to_internal(resolution, prismatic)) / np.sqrt(12)


def reading_jacobian(block: CameraBlock, model: ChainModel, x: Array) -> Array:
    """``∂(whitened pixel)/∂q`` (2D, n): each detection's two rows against its own image's
    readings (central differences)."""
    n_kin = model.n_params
    n = model.theta.shape[1]
    G = np.empty((2 * len(block.image), n))
    for k in range(n):
        step = np.zeros_like(model.theta)
        step[:, k] = STEP
        up = dataclasses.replace(model, theta=model.theta + step)
        down = dataclasses.replace(model, theta=model.theta - step)
        d = block.predict(up, x[:n_kin], x[n_kin:]) - block.predict(down, x[:n_kin], x[n_kin:])
        G[:, k] = (d / (2 * STEP * block.sigma_px[:, None])).reshape(-1)
    return G


def reading_covariance(
    block: CameraBlock, model: ChainModel, x: Array, J: Array, unscaled: Array, sigma_q: Array,
    G: Array | None = None,
) -> Array:  # fmt: skip
    """``Σ_q-part`` (P, P) of the module docstring: ``J`` (R, P) the fit's whitened
    Jacobian (its first 2D rows the pixels, any prior rows after), ``unscaled`` (P, P) its
    ``H⁻¹``, ``sigma_q`` (n,) the readings' σ (rad / cm); ``G``: :func:`reading_jacobian`
    when formed already."""
    G = reading_jacobian(block, model, x) if G is None else G
    rows = len(G)
    image = np.repeat(block.image, 2)
    m, P = len(model.theta), J.shape[1]
    K = np.zeros((m, P, G.shape[1]))  # Σ over image i's rows of J_rᵀ G_r
    np.add.at(K, image, J[:rows, :, None] * G[:, None, :])
    S = np.einsum("ipk,k,iqk->pq", K, np.asarray(sigma_q, float) ** 2, K)
    return np.asarray(unscaled @ S @ unscaled)


#: False-alarm level of the test for an error an image's points share: below it the
#: residuals along the images' pose motions are what independent pixels leave.
SHARED_ALARM = 0.01


def pose_basis(image: np.ndarray, P: Array, J_p: Array) -> list[Array]:
    """Per image of ``image`` (D,), an orthonormal basis (2 n_i, 6) of the pixels' motion
    (px, unwhitened, ``[u_1, v_1, u_2, …]``) under a small rigid motion of the target in
    the camera: a translation ``δt`` and a turn ``δω`` move a point ``P`` (D, 3, the
    camera's frame) by ``δt + δω × P``, its pixels by ``J_p`` (D, 2, 3) of that."""
    A = np.concatenate([J_p, -J_p @ _skew(P)], axis=2)  # (D, 2, 6)
    out = []
    for i in range(int(image.max()) + 1):
        rows = A[image == i].reshape(-1, 6)
        out.append(np.linalg.qr(rows)[0] if len(rows) > 6 else np.zeros((len(rows), 0)))
    return out


def reading_pose_share(block: CameraBlock, G: Array, sigma_q: Array, Q: list[Array]) -> Array:
    """Per image (M,), the readings' rounding's expected square (px²) along its pose
    basis ``Q`` (:func:`pose_basis`): ``tr(Qᵀ G Σ_q Gᵀ Q)``, ``G`` from
    :func:`reading_jacobian` (whitened: unwhitened here)."""
    n = G.shape[1]
    g = G.reshape(-1, 2, n) * block.sigma_px[:, None, None]
    sq = np.asarray(sigma_q, float) ** 2
    out = np.zeros(len(Q))
    for i, Qi in enumerate(Q):
        gi = g[block.image == i].reshape(-1, n)  # (2 n_i, n)
        proj = Qi.T @ gi
        out[i] = float(np.einsum("ak,k,ak->", proj, sq, proj))
    return out


def image_pose_variance(
    image: np.ndarray, r_px: Array, Q: list[Array], J: Array, known: Array | None = None
) -> tuple[float, float]:
    """``w²`` (px² per coordinate) of the independent pixels and ``τ²`` (px²) of an error
    shared by each image's points as a rigid motion of the target in the camera (the
    robot's pose error at that image, a lens misfit over the board's patch), from the
    fit's residuals ``r_px`` (D, 2) and its whitened Jacobian ``J`` (its first 2D rows the
    pixels), beyond ``known`` (M,) px² already counted along each image's pose basis ``Q``
    (the readings', :func:`reading_pose_share`); both 0 unless the shared error is
    significant at :data:`SHARED_ALARM` (the fit's own χ²/dof then stands).

    The model: image ``i``'s shared error is ``√n_i Q_i z_i``, ``z_i ~ N(0, τ² I₆)`` (its
    size per point independent of the number of points), beside independent pixels of
    variance ``w²``. The fit takes up part of both (its hat matrix ``H = U Uᵀ``, ``U`` an
    orthonormal basis of ``J``'s columns; with a few images, what the hand-eye and lens
    parameters absorb of the images' shared errors is large), so ``w²`` and ``τ²`` are the
    unbiased moment solution of the residuals' square along the pose bases (``Σ |Q_iᵀ
    r_i|²``) and outside them: with ``B_i = Uᵀ Q_i``, ``E |Q_iᵀ r_i|² = w² (6 − |B_i|²)
    + τ² Σ_j n_j |δ_ij I − B_jᵀ B_i|²`` and ``E |r|² = w² (2D − P) + τ² Σ_j n_j (6 −
    |B_j|²)``. The shared error is counted when the two parts' ratio, each over its
    degrees of freedom without one (``Σ (6 − |B_i|²)`` and ``2D − P − Σ (6 − |B_i|²)``),
    exceeds the F distribution's (1 − α) quantile."""
    from scipy.special import fdtri

    used = [i for i, Qi in enumerate(Q) if Qi.shape[1] == 6]
    if len(used) < 2:
        return 0.0, 0.0
    rows_of = [np.flatnonzero(np.repeat(image == i, 2)) for i in range(len(Q))]
    Jp = J[: 2 * len(image)]
    U = np.linalg.qr(Jp)[0] if Jp.shape[1] else np.zeros((len(Jp), 0))
    r = r_px.reshape(-1)
    B = [U[rows_of[i]].T @ Q[i] for i in used]  # (P, 6) each
    n_i = np.array([len(rows_of[i]) / 2 for i in used])
    p2 = np.array([float(np.sum((Q[i].T @ r[rows_of[i]]) ** 2)) for i in used])
    if known is not None:
        p2 = p2 - np.asarray(known, float)[used]
    Bs = np.stack(B)  # (M, P, 6)
    norm2 = np.einsum("ipx,ipx->i", Bs, Bs)  # |B_i|²
    a = 6.0 - norm2
    # Σ_j n_j |δ_ij I − B_jᵀ B_i|² = tr(B_iᵀ C B_i) − 2 n_i |B_i|² + 6 n_i, C = Σ n_j B_j B_jᵀ
    C = np.einsum("j,jpx,jqx->pq", n_i, Bs, Bs)
    b = np.einsum("ipx,pq,iqx->i", Bs, C, Bs) - 2.0 * n_i * norm2 + 6.0 * n_i
    total = float(r @ r) - (0.0 if known is None else float(np.sum(np.asarray(known)[used])))
    rank = int(np.linalg.matrix_rank(Jp)) if Jp.size else 0
    A = np.array([[a.sum(), b.sum()],
                  [len(r) - rank - a.sum(), float(np.sum(n_i * a)) - b.sum()]])  # fmt: skip
    try:
        w2, tau2 = np.linalg.solve(A, [p2.sum(), total - p2.sum()])
    except np.linalg.LinAlgError:
        return 0.0, 0.0
    if not (w2 > 0 and tau2 > 0):
        return 0.0, 0.0
    # without a shared error both parts are w² times χ² of Σ a and 2D − P − Σ a degrees of
    # freedom: their ratio is F-distributed
    d1, d2 = float(a.sum()), float(len(r) - rank - a.sum())
    if d2 <= 0 or (p2.sum() / d1) / ((total - p2.sum()) / d2) <= fdtri(d1, d2, 1 - SHARED_ALARM):
        return 0.0, 0.0
    return float(w2), float(tau2)


def pose_covariance(
    block: CameraBlock, J: Array, unscaled: Array, tau2_px: float, Q: list[Array]
) -> Array:
    """What the shared error of :func:`image_pose_variance` adds to the fit's covariance
    (P, P): the sandwich of the module docstring with image ``i``'s ``G_i = √n_i Q_i``
    (whitened by each point's σ), ``Σ = τ² I₆``."""
    m, P = len(Q), J.shape[1]
    S = np.zeros((P, P))
    for i in range(m):
        if Q[i].shape[1] != 6:
            continue
        rows = np.flatnonzero(np.repeat(block.image == i, 2))
        n_i = len(rows) / 2
        G = np.sqrt(n_i) * Q[i] / np.repeat(block.sigma_px[block.image == i], 2)[:, None]
        K = J[rows].T @ G  # (P, 6)
        S += K @ K.T
    return np.asarray(unscaled @ (tau2_px * S) @ unscaled)
