"""The design-model baseline: the design model with its base and tool point registered to
measured points, the "before" of a before/after (issue 29).

What a robot does uncalibrated in a cell where its base and tool were measured: the design
chain's tool point ``t`` (last D-H frame) at every pose, ``p_k = F_n(q_k) · t``, mapped by
the base ``B`` to the sensor frame; ``B`` (6) and ``t`` (3) minimise ``Σ |B p_k − m_k|²``.
The closed-form alternation of :func:`pipeline.refine.start.design_start` starts it; it
converges slowly where the base and the tool point trade off (the RCT positioner's 205
poses: 1.853 cm RMS after its 50 rounds, 0.04527 cm at the optimum), so Gauss-Newton on
the nine parameters finishes it (Levenberg-Marquardt, analytic Jacobian: a few iterations
where the alternation needs thousands of rounds).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.chain import SerialChain, frames_at, link_frames
from pipeline.kinematics.so3 import rotation_from_vector, skew
from pipeline.optim.block import Array
from pipeline.optim.lm import dense_least_squares
from pipeline.refine.start import design_start


@dataclass(frozen=True)
class DesignBaseline:
    """The registered design model: ``base`` (4, 4) sensor from design base, ``tool``
    (3,) the tool point in the last D-H frame (cm) (``points`` (T, 3): every registered
    point in its link's frame, ``tool`` the first), and its error at the points it was
    registered to (cm)."""

    chain: SerialChain
    base: Array
    tool: Array
    errors_cm: Array
    targets: Array | None = None

    def points(self, q: Array, link: Array | None = None, target: Array | None = None) -> Array:
        """The registered design's points (m, 3), sensor frame, at joint values q (rad /
        cm): the tool point, or point ``target`` (m,) of link ``link`` (m,)."""
        n = self.chain.n_joints
        link = np.full(len(q), n) if link is None else np.asarray(link)
        t = (self.tool[None] if self.targets is None else self.targets)[
            np.zeros(len(q), np.int64) if target is None else np.asarray(target)
        ]
        F = frames_at(self.chain, q, link)
        p = np.einsum("kij,kj->ki", F[:, :3, :3], t) + F[:, :3, 3]
        out: Array = p @ self.base[:3, :3].T + self.base[:3, 3]
        return out

    def errors(
        self, q: Array, measured: Array, link: Array | None = None, target: Array | None = None
    ) -> Array:
        """Distances (m,) cm of measured points from the registered design at q."""
        out: Array = np.linalg.norm(self.points(q, link, target) - measured, axis=1)
        return out


def register_design(
    chain: SerialChain, q: Array, measured: Array, tool_local: Array
) -> DesignBaseline:
    """The design ``chain`` registered to ``measured`` (K, 3) cm at joint values ``q``
    (K, n) rad / cm, its tool point started at ``tool_local`` (3,) (module docstring)."""
    start = design_start(chain, q, measured, tool_local, q[0])
    n = chain.n_joints
    return register_design_points(
        chain, q, measured, np.full(len(q), n), np.zeros(len(q), np.int64), start.base
    )


def register_design_points(
    chain: SerialChain, q: Array, measured: Array, link: Array, target: Array, base0: Array
) -> DesignBaseline:
    """The design ``chain`` registered to ``measured`` (K, 3) cm at joint values ``q``
    (K, n) rad / cm, each row a point ``target`` (K,) (0..T−1) fixed on link ``link``
    (K,) (the frame ``link_frames(chain, q)[:, link]``; the tool point: link n): the
    base ``B`` (6) and the T points (3 each) minimising ``Σ |B F_link(q_k) t_k − m_k|²``,
    started at the base ``base0`` (4, 4), each point given ``base0`` in closed form
    (the least-squares point, ``R_k`` orthonormal), then Gauss-Newton (module
    docstring). Used for the tool point (:func:`register_design`) and for the joint
    sweeps' link targets (the design's held-out errors of stage ``holdout``)."""
    target = np.asarray(target, np.int64)
    F = frames_at(chain, q, link)
    R_k, o_k = F[:, :3, :3], F[:, :3, 3]
    B0 = base0
    local = ((measured - B0[:3, 3]) @ B0[:3, :3]) - o_k  # B0⁻¹ m_k − o_k
    T = int(target.max()) + 1
    t0 = np.zeros((T, 3))
    for j in range(T):  # the least-squares point of each target given B0
        at = target == j
        t0[j] = np.linalg.lstsq(R_k[at].reshape(-1, 3), local[at].reshape(-1), rcond=None)[0]

    def unpack(x: Array) -> tuple[Array, Array, Array]:
        R = rotation_from_vector(x[:3]) @ B0[:3, :3]
        return R, x[3:6], x[6:].reshape(T, 3)

    def residuals(x: Array) -> Array:
        R, b, t = unpack(x)
        p = np.einsum("kij,kj->ki", R_k, t[target]) + o_k
        r: Array = (p @ R.T + b - measured).reshape(-1)
        return r

    def jacobian(x: Array) -> Array:
        R, _, t = unpack(x)
        # ∂(exp(ω)·Rp)/∂ω is −[Rp]× at ω = 0, times an invertible 3 × 3 elsewhere: the same
        # stationary points, so the optimum is exact.
        Rp = (np.einsum("kij,kj->ki", R_k, t[target]) + o_k) @ R.T
        J = np.zeros((len(measured), 3, 6 + 3 * T))
        J[:, :, :3] = -skew(Rp)
        J[:, :, 3:6] = np.eye(3)
        for j in range(T):
            J[target == j, :, 6 + 3 * j : 9 + 3 * j] = R @ R_k[target == j]
        out: Array = J.reshape(-1, 6 + 3 * T)
        return out

    x0 = np.r_[np.zeros(3), B0[:3, 3], t0.reshape(-1)]
    x = dense_least_squares(residuals, jacobian, x0).x  # 1e-15: a noiseless audit
    R, b, t = unpack(x)
    base = np.eye(4)
    base[:3, :3], base[:3, 3] = R, b
    errors = np.linalg.norm(residuals(x).reshape(-1, 3), axis=1)
    return DesignBaseline(chain, base, t[0], errors, t)


@dataclass(frozen=True)
class OffsetsFit:
    """``chain`` with only its joint offsets, its base and its tool point fitted to points:
    ``offsets`` (n,) added to the readings (rad / cm; 0 where ``held``), ``base`` (4, 4)
    the chain's world in the points' frame, ``tool`` (3,) in the last link frame (cm),
    and each point's distance from the fit (cm)."""

    offsets: Array
    base: Array
    tool: Array
    errors_cm: Array
    held: npt.NDArray[np.bool_]


def register_offsets(
    chain: SerialChain, q: Array, measured: Array, base0: Array, held: npt.NDArray[np.bool_]
) -> OffsetsFit:
    """The joint offsets ``δ``, base ``B`` and tool point ``t`` minimising
    ``Σ |B F_n(q_k + δ) t − m_k|²`` (``measured`` (K, 3) cm at readings ``q`` (K, n)),
    ``δ_j`` held at 0 where ``held`` (n,); started at :func:`register_design_points`'s
    base and tool (``δ = 0``), then Gauss-Newton on all of them (its Jacobian: the tool
    point turned about joint ``j``'s axis, ``z_j × (p − o_j)``, or moved along it)."""
    n = chain.n_joints
    start = register_design_points(
        chain, q, measured, np.full(len(q), n), np.zeros(len(q), np.int64), base0
    )
    free = ~np.asarray(held, bool)
    B0, pris = start.base, np.asarray(chain.prismatic, bool)

    def unpack(x: Array) -> tuple[Array, Array, Array, Array]:
        delta = np.zeros(n)
        delta[free] = x[9:]
        return rotation_from_vector(x[:3]) @ B0[:3, :3], x[3:6], x[6:9], delta

    def frames(x: Array) -> tuple[Array, Array, Array, Array]:
        R, b, t, delta = unpack(x)
        F = link_frames(chain, q + delta)
        p = np.einsum("kij,j->ki", F[:, n, :3, :3], t) + F[:, n, :3, 3]  # in the world
        return R, b, F, p

    def residuals(x: Array) -> Array:
        R, b, _, p = frames(x)
        r: Array = (p @ R.T + b - measured).reshape(-1)
        return r

    def jacobian(x: Array) -> Array:
        R, _, F, p = frames(x)
        J = np.zeros((len(q), 3, 9 + int(free.sum())))
        J[:, :, :3] = -skew(p @ R.T)  # as register_design_points: the same stationary points
        J[:, :, 3:6] = np.eye(3)
        J[:, :, 6:9] = R @ F[:, n, :3, :3]
        z, o = F[:, :n, :3, 2], F[:, :n, :3, 3]  # joint j's axis: frame j − 1's z
        turn = np.cross(z, p[:, None, :] - o)
        dp = np.where(pris[None, :, None], z, turn)  # (K, n, 3)
        J[:, :, 9:] = np.einsum("ij,knj->kin", R, dp[:, free])
        out: Array = J.reshape(-1, J.shape[-1])
        return out

    x0 = np.r_[np.zeros(3), B0[:3, 3], start.tool, np.zeros(int(free.sum()))]
    x = dense_least_squares(residuals, jacobian, x0).x  # 1e-15: a noiseless audit
    R, b, t, delta = unpack(x)
    base = np.eye(4)
    base[:3, :3], base[:3, 3] = R, b
    errors = np.linalg.norm(residuals(x).reshape(-1, 3), axis=1)
    return OffsetsFit(delta, base, t, errors, ~free)
