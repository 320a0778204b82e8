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
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.optim.block import Array
from pipeline.refine.camera_block import CameraBlock
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
    block: CameraBlock, model: ChainModel, x: Array, J: Array, unscaled: Array, sigma_q: Array
) -> Array:
    """``Σ_q-part`` (P, P) of the module docstring: ``J`` (R, P) the fit's whitened
    Jacobian (its first 2D rows the pixels, any prior rows after), ``unscaled`` (P, P) its
    ``H⁻¹``, ``sigma_q`` (n,) the readings' σ (rad / cm)."""
    G = reading_jacobian(block, model, x)
    rows = len(G)
    image = np.repeat(block.image, 2)
    m, P = len(model.theta), J.shape[1]
    K = np.zeros((m, P, G.shape[1]))  # Σ over image i's rows of J_rᵀ G_r
    np.add.at(K, image, J[:rows, :, None] * G[:, None, :])
    S = np.einsum("ipk,k,iqk->pq", K, np.asarray(sigma_q, float) ** 2, K)
    return np.asarray(unscaled @ S @ unscaled)
