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

from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.kinematics.so3 import rotation_from_vector, skew
from pipeline.optim.block import Array
from pipeline.refine.start import design_start


@dataclass(frozen=True)
class DesignBaseline:
    """The registered design model: ``base`` (4, 4) sensor from design base, ``tool``
    (3,) the tool point in the last D-H frame (cm), and its error at the points it was
    registered to (cm)."""

    chain: SerialChain
    base: Array
    tool: Array
    errors_cm: Array

    def points(self, q: Array) -> Array:
        """The registered design's tool point (m, 3), sensor frame, at joint values q (rad / cm)."""
        flange = link_frames(self.chain, q)[:, self.chain.n_joints]
        p = flange[:, :3, :3] @ self.tool + flange[:, :3, 3]
        out: Array = p @ self.base[:3, :3].T + self.base[:3, 3]
        return out

    def errors(self, q: Array, measured: Array) -> Array:
        """Distances (m,) cm of measured points from the registered design at q."""
        out: Array = np.linalg.norm(self.points(q) - measured, axis=1)
        return out


def register_design(
    chain: SerialChain, q: Array, measured: Array, tool_local: Array
) -> DesignBaseline:
    """The design ``chain`` registered to ``measured`` (K, 3) cm at joint values ``q``
    (K, n) rad / cm, its tool point started at ``tool_local`` (3,) (module docstring)."""
    from scipy.optimize import least_squares

    start = design_start(chain, q, measured, tool_local, q[0])
    n = chain.n_joints
    flange = link_frames(chain, q)[:, n]
    R_k, o_k = flange[:, :3, :3], flange[:, :3, 3]
    B0 = start.base
    # The start's tool point, back in the last D-H frame (design_start reports it at q̄^s).
    t0 = np.linalg.lstsq(
        R_k.reshape(-1, 3),
        (((measured - B0[:3, 3]) @ B0[:3, :3]) - o_k).reshape(-1),
        rcond=None,
    )[0]

    def unpack(x: Array) -> tuple[Array, Array, Array]:
        R = rotation_from_vector(x[:3]) @ B0[:3, :3]
        return R, x[3:6], x[6:]

    def residuals(x: Array) -> Array:
        R, b, t = unpack(x)
        p = R_k @ t + o_k
        r: Array = (p @ R.T + b - measured).reshape(-1)
        return r

    def jacobian(x: Array) -> Array:
        R, _, t = unpack(x)
        # ∂(exp(ω)·Rp)/∂ω is −[Rp]× at ω = 0, times an invertible 3 × 3 elsewhere: the same
        # stationary points, so the optimum is exact.
        Rp = (R_k @ t + o_k) @ R.T
        J = np.zeros((len(measured), 3, 9))
        J[:, :, :3] = -skew(Rp)
        J[:, :, 3:6] = np.eye(3)
        J[:, :, 6:] = R @ R_k
        out: Array = J.reshape(-1, 9)
        return out

    x0 = np.r_[np.zeros(3), B0[:3, 3], t0]
    sol = least_squares(residuals, x0, jac=jacobian, method="lm", xtol=1e-15, ftol=1e-15)
    R, b, t = unpack(sol.x)
    base = np.eye(4)
    base[:3, :3], base[:3, 3] = R, b
    errors = np.linalg.norm(residuals(sol.x).reshape(-1, 3), axis=1)
    return DesignBaseline(chain, base, t, errors)
