"""From identified frames to a signature model (Sections 4.3.3-4.3.5).

The signature model is (ERRATA.md)
``T(q) = S̄_0 · Π_i M_i(q_i − q̄_i^s) · B_i · tool`` with ``B_i = S̄_{i−1}⁻¹ S̄_i``
(4.51) and ``M_i`` a rotation about (or translation along) z. It is a
:class:`SerialChain` with ``base = S̄_0``, ``links = B``, ``joint_offsets = q̄^s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.smodel import SModelParams, dh_from_smodel, smodel_from_matrix
from pipeline.kinematics.transforms import (
    Array,
    ArrayLike,
    invert_transform,
    rot_z,
    trans_z,
    wrap_angle,
)


def frame_from_features(axis: ArrayLike, origin: ArrayLike, toward: ArrayLike) -> Array:
    """S-Model link frame ``S̄_i`` from joint ``i+1``'s features, (4.49)-(4.50).

    Parameters
    ----------
    axis : array_like, shape (..., 3)
        Unit plane normal (revolute) or line direction (prismatic), in the
        positive sense of the joint.
    origin : array_like, shape (..., 3)
        Centre of rotation (revolute) or a point on the line (prismatic), cm.
    toward : array_like, shape (..., 3)
        A point the X axis points to after projection onto the plane through
        ``origin`` normal to ``axis``: the first target position (4.50).

    Returns
    -------
    S : ndarray, shape (..., 4, 4)
    """
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    p = np.asarray(origin, float)
    v = np.asarray(toward, float) - p
    # Eq. (4.50): the first target position projected onto the plane
    n = v - (v[..., None, :] @ a[..., :, None])[..., 0] * a
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    S = np.zeros((*n.shape[:-1], 4, 4))
    S[..., 3, 3] = 1.0
    S[..., :3, 0] = n
    S[..., :3, 1] = np.cross(a, n)  # o = a × n
    S[..., :3, 2] = a
    S[..., :3, 3] = p  # Eq. (4.49)
    return S


def frames_at_signature(
    frames: ArrayLike, readings: ArrayLike, q_signature: ArrayLike, prismatic: ArrayLike
) -> Array:
    """Frames measured each at its own sweep's readings, brought to ``q̄^s``.

    ``S̄_{i−1}`` is fixed in link ``i−1``; sweep ``i`` measures it with joints
    ``1 … i−1`` at that sweep's readings ``r`` (a held joint may re-settle between
    sweeps), not at ``q̄^s``. With the link pose ``L(q) = S̄_0 Π_j M_j(q_j − q̄_j^s) B_j``
    of the signature model (module docstring), the frame at ``q̄^s`` is
    ``C · S̄_{i−1}`` with ``C = L_{i−1}(q̄^s) L_{i−1}(r)^{-1}``; ``B_{i−1}`` cancels in
    ``C``, so ``C`` needs only ``S̄_0 … S̄_{i−2}``, already brought to ``q̄^s``:
    the frames are corrected in order, sweep 2 to n (sweep 1 has no earlier joint).
    ``C`` is a rigid motion, so moving the frame moves its features (axis, centre
    or line point, first target) with it, and (4.49)-(4.50) give the same frame.
    Exact for exact features and readings.

    Parameters
    ----------
    frames : array_like, shape (n, 4, 4)
        ``S̄_0 … S̄_{n−1}``, ``S̄_{i−1}`` from sweep ``i``'s features (cm).
    readings : array_like, shape (n, n)
        Row ``i−1``: the joint readings while sweep ``i`` was measured (rad / cm;
        only joints ``1 … i−1`` are used).
    q_signature : array_like, shape (n,)
        ``q̄^s`` (rad / cm).
    prismatic : array_like of bool, shape (n,)

    Returns
    -------
    ndarray, shape (n, 4, 4)
    """
    F = np.array(frames, float)
    r = np.asarray(readings, float)
    qs = np.asarray(q_signature, float)
    pris = np.asarray(prismatic, bool)
    for i in range(2, len(F) + 1):
        m = i - 1  # joints 1 … i−1 move link i−1
        if np.array_equal(r[i - 1, :m], qs[:m]):
            continue  # already at q̄^s: C = I exactly (no rounding from a product with its inverse)
        # L_{i−1} with B_{i−1} = I (it cancels): frames S̄_0 … S̄_{i−2} and S̄_{i−2} again.
        chain = signature_chain(np.concatenate([F[:m], F[m - 1 : m]]), qs[:m], pris[:m])
        at_sweep = forward_kinematics(chain, r[i - 1, :m])
        F[i - 1] = forward_kinematics(chain, qs[:m]) @ invert_transform(at_sweep) @ F[i - 1]
    return F


def links_from_frames(frames: ArrayLike) -> Array:
    """``B_i = S̄_{i−1}⁻¹ S̄_i`` (4.51) for frames of shape (..., n+1, 4, 4) -> (..., n, 4, 4)."""
    F = np.asarray(frames, float)
    B: Array = invert_transform(F[..., :-1, :, :]) @ F[..., 1:, :, :]
    return B


def signature_chain(
    frames: ArrayLike, q_signature: ArrayLike, prismatic: ArrayLike, tool: ArrayLike | None = None
) -> SerialChain:
    """The signature model as a serial chain.

    Parameters
    ----------
    frames : array_like, shape (..., n+1, 4, 4)
        ``S̄_0 … S̄_n`` in the sensor frame (cm); a leading batch shape gives
        a batch of robots sharing ``q_signature``.
    q_signature : array_like, shape (n,)
        Encoder readings ``q̄^s`` at which each ``S̄_i`` holds (rad / cm).
    prismatic : array_like of bool, shape (n,)
    tool : array_like, shape (..., 4, 4), optional
        Tool in the last S-Model frame ``S_n``.
    """
    F = np.asarray(frames, float)
    return SerialChain(
        links=links_from_frames(F),
        prismatic=np.asarray(prismatic, bool),
        base=F[..., 0, :, :],
        tool=np.eye(4) if tool is None else np.asarray(tool, float),
        joint_offsets=np.asarray(q_signature, float),
    )


@dataclass(frozen=True)
class PseudoDH:
    """Pseudo D-H model (4.71)-(4.73) that reproduces a signature chain exactly.

    ``A_i = Rot(z, θ_i) Trans(0, 0, d_i) Trans(a_i, 0, 0) Rot(x, α_i)`` where for a
    revolute joint ``θ_i = q_i + q_offset_i`` and for a prismatic joint
    ``d_i = q_i + q_offset_i`` (q = encoder reading). ``T(q) = base · Π A_i · tool``.
    Arrays of shape (..., n) (``base``, ``tool``: (..., 4, 4)); angles in radians,
    lengths in cm. ``smodel`` holds the S-Model links the parameters come from.
    """

    q_offset: Array
    theta: Array  # constant θ_i of prismatic joints (NaN for revolute)
    d: Array  # constant d_i of revolute joints (NaN for prismatic)
    a: Array
    alpha: Array
    base: Array
    tool: Array
    smodel: SModelParams


def pseudo_dh_from_smodel(
    sm: SModelParams,
    prismatic: ArrayLike,
    joint_offsets: ArrayLike,
    base: ArrayLike,
    tool: ArrayLike,
) -> PseudoDH:
    """Encoder offsets (4.59)/(4.60) and D-H parameters (3.12)-(3.15) of S-Model links.

    ``θ_i = β_i + γ_{i−1}`` and ``d_i = d̄_i + b_{i−1}`` with ``γ_0 = b_0 = 0``
    because the base frame is ``S_0`` itself (4.71); the leftover
    ``Rot(z, γ_n) Trans(0, 0, b_n)`` of the last link moves into the tool.

    Parameters
    ----------
    sm : SModelParams
        Arrays of shape (..., n), link ``i`` in the last axis.
    prismatic : array_like of bool, shape (n,)
    joint_offsets : array_like, shape (n,)
        Encoder readings ``q̄^s`` at the signature configuration (rad / cm).
    base, tool : array_like, shape (..., 4, 4)
        ``S̄_0`` and the tool in ``S_n``.
    """
    dh = dh_from_smodel(sm)  # Eq. (3.12)-(3.15)
    pris = np.asarray(prismatic, bool)
    qs = np.asarray(joint_offsets, float)
    # Eq. (4.59): offset = D-H value at q^s minus the encoder reading there; (4.72)/(4.73)
    q_offset = np.where(pris, dh.d - qs, wrap_angle(dh.theta - qs))
    tail = rot_z(sm.gamma[..., -1]) @ trans_z(sm.b[..., -1])
    return PseudoDH(
        q_offset=q_offset,
        theta=np.where(pris, wrap_angle(dh.theta), np.nan),
        d=np.where(pris, np.nan, dh.d),
        a=dh.a,  # Eq. (3.14)
        alpha=dh.alpha,  # Eq. (3.15)
        base=np.asarray(base, float),
        tool=tail @ np.asarray(tool, float),
        smodel=sm,
    )


def pseudo_dh_from_chain(chain: SerialChain) -> PseudoDH:
    """Pseudo D-H model (4.71) of a signature chain, its S-Model links taken as they are.

    For prismatic joints the result is the *modified* D-H model (``a_i ≠ 0``);
    :func:`pipeline.kinematics.true_dh.true_dh_from_chain` gives the true one.
    Batched: ``chain.links`` may have shape (..., n, 4, 4).
    """
    return pseudo_dh_from_smodel(
        smodel_from_matrix(chain.links),
        chain.prismatic,
        np.asarray(chain.joint_offsets, float),
        chain.base,
        chain.tool,
    )


def chain_from_pseudo_dh(p: PseudoDH, prismatic: ArrayLike) -> SerialChain:
    """The pseudo D-H model as a serial chain (for checking it against the signature)."""
    from pipeline.kinematics.chain import chain_from_dh

    pris = np.asarray(prismatic, bool)
    return chain_from_dh(
        theta=np.where(pris, p.theta, p.q_offset),
        d=np.where(pris, p.q_offset, p.d),
        a=p.a,
        alpha=p.alpha,
        prismatic=pris,
        base=p.base,
        tool=p.tool,
    )
