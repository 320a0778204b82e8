"""Joint motions about axis lines in closed form, on contiguous arrays of the observations.

Joint ``k``'s motion ``A_k(θ) = S_k M(θ) S_k⁻¹`` (:mod:`pipeline.refine.kinematics`) is the
rotation by ``θ`` about its axis line, direction ``ω`` (``S_k``'s z, unit) through ``c``
(``S_k``'s origin): ``R = I + sin θ [ω]× + (1 − cos θ) [ω]×²`` (Rodrigues), ``t = c − R c``;
or, prismatic, the translation ``θ ω``. At ``θ = 0`` both are exactly the identity.

Rigid motions of K observations are kept with the observations last: a rotation by its
columns, ``Q`` (…, 3, 3, K) with ``Q[…, j, :, k]`` = ``R_k e_j``, a translation ``t``
(…, 3, K). A product or a rotated vector is then a few component products of contiguous
(K,) arrays, and a rotation of constant vectors one matrix product (BLAS), where (K, 4, 4)
stacks of matrix products took most of a fit (issue 45).

A twist ``(w, v)`` (``G p = w × p + v``) acting after a prefix ``P = (R, t)`` moves the
point ``p = P u`` by ``P G P⁻¹ p = R w × (p − t) + R v``: every derivative of the chain
model is such a product, formed on the point itself.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.so3 import skew

Array = npt.NDArray[np.float64]


def trig_basis(theta: Array) -> Array:
    """``(1, sin θ, 1 − cos θ)`` (n, 3, K) of joint values ``theta`` (n, K): what a joint's
    motion is linear in (:func:`joint_motions`)."""
    n, K = theta.shape
    basis = np.empty((n, 3, K))
    basis[:, 0] = 1.0
    np.sin(theta, out=basis[:, 1])
    np.cos(theta, out=basis[:, 2])
    np.subtract(1.0, basis[:, 2], out=basis[:, 2])
    return basis


def joint_motions(
    frames: Array,
    prismatic: npt.NDArray[np.bool_],
    theta: Array,
    basis: Array | None = None,
    out: Array | None = None,
) -> tuple[Array, Array]:
    """``A_k(θ_k)`` of every joint and observation: columns ``Q`` (n, 3, 3, K) and
    translations ``t`` (n, 3, K), for joint values ``theta`` (n, K) (rad / cm) and the
    joints' frames ``S_k`` (n, 4, 4) (module docstring); ``basis``: their
    :func:`trig_basis` when already formed; ``out`` (n, 12, K): where to write them (views
    of it are returned: a buffer reused joint after joint spares the allocator's fresh
    pages, a third of the positions' time at 20,000 rows)."""
    n, K = theta.shape
    w, c = frames[:, :3, 2], frames[:, :3, 3]
    W = skew(w)  # (n, 3, 3)
    W2 = W @ W
    # Each of the twelve components is a fixed combination of (1, sin θ, 1 − cos θ):
    # Q[j, i] = R[i, j] = I[i, j] + sin θ W[i, j] + (1 − cos θ) W²[i, j] and
    # t = c − R c = −sin θ W c − (1 − cos θ) W² c; one matrix product per joint.
    coef = np.zeros((n, 12, 3))
    coef[:, :9, 0] = np.eye(3).ravel()
    coef[:, :9, 1] = np.swapaxes(W, 1, 2).reshape(n, 9)
    coef[:, :9, 2] = np.swapaxes(W2, 1, 2).reshape(n, 9)
    coef[:, 9:, 1] = -(W @ c[..., None])[..., 0]
    coef[:, 9:, 2] = -(W2 @ c[..., None])[..., 0]
    out = np.matmul(coef, trig_basis(theta) if basis is None else basis, out=out)  # (n, 12, K)
    Q, t = out[:, :9].reshape(n, 3, 3, K), out[:, 9:]
    if prismatic.any():
        Q[prismatic] = np.eye(3)[:, :, None]
        t[prismatic] = w[prismatic][..., None] * theta[prismatic][:, None]
    return Q, t


def rotate(Q: Array, v: Array) -> Array:
    """``R v`` (3, K) of per-observation vectors ``v`` (3, K), ``Q`` (3, 3, K)."""
    out: Array = Q[0] * v[0] + Q[1] * v[1] + Q[2] * v[2]
    return out


def rotate_constant(Q: Array, w: Array) -> Array:
    """``R w_m`` (m, 3, K) of constant vectors ``w`` (m, 3), ``Q`` (3, 3, K): one matrix
    product."""
    K = Q.shape[-1]
    out: Array = (w @ Q.reshape(3, 3 * K)).reshape(len(w), 3, K)
    return out


def compose(Qa: Array, ta: Array, Qb: Array, tb: Array) -> tuple[Array, Array]:
    """``(R_a R_b, R_a t_b + t_a)`` of two motions (3, 3, K), (3, K)."""
    Q = np.empty_like(Qb)
    for j in range(3):
        Q[j] = rotate(Qa, Qb[j])
    return Q, rotate(Qa, tb) + ta


def prefixes(motion: Callable[[int], tuple[Array, Array]], n: int) -> tuple[Array, Array]:
    """``Π_{i<k} A_i`` for k = 0..n (columns (n + 1, 3, 3, K), translations (n + 1, 3, K))
    of the motions ``motion(i)`` (columns (3, 3, K), translation (3, K)) of joints
    i = 0..n − 1, each formed when its product is (one joint's motions in memory at a
    time beside the prefixes); the first is the identity."""
    Q, t = motion(0)
    K = Q.shape[-1]
    QP = np.empty((n + 1, 3, 3, K))
    tP = np.empty((n + 1, 3, K))
    QP[0] = np.eye(3)[:, :, None]
    tP[0] = 0.0
    QP[1], tP[1] = Q, t
    for k in range(1, n):
        QP[k + 1], tP[k + 1] = compose(QP[k], tP[k], *motion(k))
    return QP, tP


def cross(a: Array, b: Array) -> Array:
    """``a × b`` along the component axis (the second last) of (…, 3, K) arrays."""
    return np.stack(
        [
            a[..., 1, :] * b[..., 2, :] - a[..., 2, :] * b[..., 1, :],
            a[..., 2, :] * b[..., 0, :] - a[..., 0, :] * b[..., 2, :],
            a[..., 0, :] * b[..., 1, :] - a[..., 1, :] * b[..., 0, :],
        ],
        axis=-2,
    )


def moved_by_twists(Q: Array, t: Array, p: Array, w: Array, v: Array) -> Array:
    """``R w_m × (p − t) + R v_m`` (m, 3, K): the point ``p`` (3, K) moved by the twists
    ``(w, v)`` (m, 3) each acting after the prefix ``(R, t)`` (module docstring)."""
    m = len(w)
    rotated = rotate_constant(Q, np.concatenate([w, v]))
    out: Array = cross(rotated[:m], p - t) + rotated[m:]
    return out


def vee(W: Array) -> Array:
    """Axial vectors (..., 3) of the skew parts of (..., 3, 3) matrices."""
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]],
        axis=-1,
    )


def twists(G: Array) -> tuple[Array, Array]:
    """``(w, v)`` (…, 3) of se(3) matrices ``G`` (…, 4, 4): ``G p = w × p + v``."""
    return vee(G[..., :3, :3]), G[..., :3, 3]


def by_observation(Q: Array) -> Array:
    """Rotation matrices (K, 3, 3) of columns ``Q`` (3, 3, K)."""
    return np.ascontiguousarray(Q.transpose(2, 1, 0))
