"""The rigid chain that best reproduces a signature with non-geometric terms (issue 43).

A signature with non-geometric terms (:mod:`pipeline.kinematics.nongeometric`) puts the
tool point at ``p(q) = T(q + Δ(q))·o`` for a reading ``q``: the rigid chain ``T``
evaluated where gravity, the payload and the joints' angle errors put the joints. A file
that holds a rigid chain only (URDF, the D-H tables, the chain JSON, a vendor's URDF)
cannot state ``Δ``; the best it can hold is the rigid chain ``C`` minimising

    ``Σ_k |p_C(q_k) − p(q_k)|²``  over configurations ``q_k`` within the joint limits,

with ``Δ`` under the payload and gravity the signature was identified with. ``C`` is the
refinement's own model (:class:`~pipeline.refine.kinematics.ChainModel`: each joint's
axis line and the tool point) started at the signature's rigid chain and fitted by the
refinement's solver (:func:`pipeline.refine.solve.solve`) with the plain squared loss:
the same parameters, gauge and Jacobian as the identification, no second solver. The
parameters the session's fit held (``held``: not identifiable from its points, such as
the last joint's direction when the tool point lies on its axis) and those the sample
itself cannot see (:func:`pipeline.refine.identifiability.analyse`, structural only)
stay at the signature's values.

The chain keeps the signature's gauge: frame ``S̄_{i−1}`` moved the least onto the fitted
axis of joint ``i``, the encoder offsets ``q̄^s``, and the tool's orientation in the last
frame (it is not seen by points).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from pipeline.kinematics.chain import SerialChain, forward_kinematics, link_frames
from pipeline.kinematics.nongeometric import NonGeometric
from pipeline.kinematics.signature import signature_chain
from pipeline.optim.block import Array
from pipeline.refine.identifiability import analyse
from pipeline.refine.kinematics import TOOL_POINT, ChainModel
from pipeline.refine.points import PointBlock
from pipeline.refine.solve import Problem, residuals_and_jacobian, solve


@dataclass(frozen=True)
class RigidFit:
    """The best rigid ``chain``, its tool point's distance from the full signature's at
    each sampled configuration (``errors_cm``, (m,)), the same for the signature's own
    rigid chain (``rigid_errors_cm``), the parameters held at the signature's values, and
    the solver's summary."""

    chain: SerialChain
    errors_cm: Array
    rigid_errors_cm: Array
    held: tuple[str, ...]
    iterations: int
    status: str

    @property
    def rms_cm(self) -> float:
        return float(np.sqrt(np.mean(self.errors_cm**2)))

    @property
    def max_cm(self) -> float:
        return float(self.errors_cm.max())


def tool_model(chain: SerialChain, q: Array) -> tuple[ChainModel, Array]:
    """The refinement's model of ``chain``'s tool point at readings ``q`` (m, n), rad /
    cm, and its parameters ``x0`` that reproduce ``chain`` (every axis move 0, the tool
    point at the signature configuration ``q̄^s = joint_offsets``)."""
    n, q0 = chain.n_joints, np.asarray(chain.joint_offsets, float)
    F = link_frames(chain, q0)  # S̄_0 … S̄_n and the tool, at q̄^s
    m = len(q)
    model = ChainModel(
        frames0=F[:n],
        prismatic=np.asarray(chain.prismatic, bool),
        link=np.full(m, n, np.int64),
        theta=np.asarray(q, float) - q0,
        point=np.zeros(m, np.int64),
        point_names=(TOOL_POINT,),
    )
    x0 = np.zeros(model.n_params)
    x0[model.point_slice(0)] = F[-1, :3, 3]
    return model, x0


def chain_of(model: ChainModel, x: Array, like: SerialChain) -> SerialChain:
    """The chain of parameters ``x`` in ``like``'s gauge (module docstring): its
    ``q̄^s``, and the tool turned in the last frame as ``like``'s is in ``S̄_{n−1}``."""
    F = model.signature_frames(x, 0)  # S̄_0 … S̄_{n−1}, S̄_n = S̄_{n−1}, tool
    n, q0 = model.n_joints, np.asarray(like.joint_offsets, float)
    old = link_frames(like, q0)
    tool = F[-1].copy()
    tool[:3, :3] = old[n - 1, :3, :3].T @ old[-1, :3, :3]  # the tool's turn in S̄_{n−1}
    return signature_chain(F[: n + 1], q0, like.prismatic, tool)


def best_rigid_chain(
    chain: SerialChain, nongeometric: NonGeometric, q: Array, held: tuple[str, ...] = ()
) -> RigidFit:
    """The rigid chain nearest the signature (``chain`` with ``nongeometric``) at the
    tool point over readings ``q`` (m, n), rad / cm; ``held``: parameter names
    (:attr:`ChainModel.param_names`) kept at the signature's values (module docstring)."""
    full = forward_kinematics(chain, nongeometric.effective(q))[:, :3, 3]
    model, x0 = tool_model(chain, q)
    block = PointBlock(pa.table({}), full, np.broadcast_to(np.eye(3), (len(q), 3, 3)))
    problem = Problem(model, block, loss="linear")
    _, J = residuals_and_jacobian(problem, x0)
    seen = analyse(J, model.param_units, noise_stated=False, n_points=len(q))
    hold = seen.held | np.isin(model.param_names, held)
    sol = solve(Problem(model, block, loss="linear", held=hold), x0)
    errors = np.linalg.norm(model.positions(sol.x) - full, axis=1)
    rigid = np.linalg.norm(model.positions(x0) - full, axis=1)
    names = tuple(str(p) for p, h in zip(model.param_names, hold, strict=True) if h)
    return RigidFit(chain_of(model, sol.x, chain), errors, rigid, names, sol.iterations, sol.status)
