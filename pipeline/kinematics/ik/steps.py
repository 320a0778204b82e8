"""Increments of the Newton-Raphson iteration (5.4): the unit-scaled SVD, the
Newton and damped least-squares steps, and the per-joint step cap."""

from __future__ import annotations

import numpy as np

from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import Array


def _unit_weights(length: float) -> Array:
    """Row weights ``[1/L, 1/L, 1/L, 1, 1, 1]`` that make δ and J unit-scaled."""
    return np.array([1.0 / length] * 3 + [1.0] * 3)


def _scaled_svd(J: Array, length: float) -> tuple[Array, Array, Array]:
    """SVD of the Jacobian with its position rows divided by ``length``."""
    U, s, Vt = np.linalg.svd(J * _unit_weights(length)[:, None], full_matrices=False)
    return U, s, Vt


def _damped_step(U: Array, s: Array, Vt: Array, delta_scaled: Array, lam: Array) -> Array:
    """Damped least-squares solution of the scaled ``J dq = δ`` (5.4) from its SVD.

    Parameters
    ----------
    U, s, Vt : ndarray, shapes (k, 6, r), (k, r), (k, r, n)
        SVD of the Jacobian with position rows divided by the length scale.
    delta_scaled : ndarray, shape (k, 6)
        δ with the position part divided by the same length scale.
    lam : ndarray, shape (k,)
        Levenberg-Marquardt damping λ (0: the Newton step ``J⁻¹ δ``).

    Returns
    -------
    dq : ndarray, shape (k, n)
        ``V diag(σ / (σ² + λ²)) Uᵀ δ``. Singular values below 1e-12 σ_max are
        dropped (pseudo-inverse cut-off: far above the ~1e-16 round-off of the
        SVD, far below any physical σ; the Puma's σ_min one encoder count from
        its wrist singularity is ~1e-4), so the step is finite for every finite J.
    """
    keep = s > 1e-12 * s[:, :1]
    gain = np.where(keep, s / np.where(keep, s**2 + lam[:, None] ** 2, 1.0), 0.0)
    coeff = np.einsum("kij,ki->kj", U, delta_scaled) * gain
    dq: Array = np.einsum("kjn,kj->kn", Vt, coeff)
    return dq


def _newton_step(J: Array, delta: Array, length: float) -> Array:
    """The Newton increment ``dq = J⁻¹ δ`` of (5.4), rows (k, 6, n) and (k, 6).

    A square Jacobian is solved by LU (row scaling does not change the
    solution); an exactly singular or non-square one by the SVD pseudo-inverse
    of the unit-scaled Jacobian (minimum-norm least squares, see
    :func:`_damped_step`).
    """
    k, _, n = J.shape
    if n == 6 and k:
        try:
            dq = np.linalg.solve(J, delta[..., None])[..., 0]
            if np.count_nonzero(np.isfinite(dq)) == dq.size:
                return np.asarray(dq, float)
        except np.linalg.LinAlgError:
            pass
    U, sv, Vt = _scaled_svd(J, length)
    return _damped_step(U, sv, Vt, delta * _unit_weights(length), np.zeros(k))


def _cap_step(dq: Array, limit: Array | float) -> Array:
    """Scale each step so no increment exceeds its ``limit`` (n,).

    The limit is ``max_step`` rad for a revolute joint and ``max_step · length``
    cm for a prismatic one (:func:`_step_limit`). Far from the solution (or at a
    singularity) the linearisation is poor and a full step can throw the
    iterate onto another branch; a uniform scale keeps its direction.
    """
    size = np.abs(dq)
    if np.count_nonzero(size <= limit) == size.size:  # the common case: nothing to scale
        return dq
    worst = np.max(size / limit, axis=-1)
    capped: Array = dq / np.maximum(worst, 1.0)[:, None]
    return capped


def _step_limit(chain: SerialChain, max_step: float, length: float) -> Array | float:
    """Per-joint step limits (n,) of :func:`_cap_step`: rad, or cm for prismatic joints
    (one number for a chain of revolute joints)."""
    if not chain.motion_basis[2]:
        return max_step
    return np.where(chain.prismatic, max_step * length, max_step)
