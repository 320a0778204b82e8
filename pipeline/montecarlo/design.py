"""Design-model control of manufactured Puma 560s (Sections 7.2.2, 7.4.1, 7.4.2).

Each robot is model (7.1)-(7.8) with its own ε (:func:`draw_puma_eps`). The
controller knows only the design model: it commands the closed-form design
inverse of the Table 7-1 poses (flange poses in the ideal base frame, branch
:data:`GRID_BRANCH`) and the robot goes wherever its true kinematics take
those encoder readings. Joint limits are not applied (the thesis does not
mention them; no branch keeps all 12 vertices inside the Puma's limits).
"""

from __future__ import annotations

from functools import cache

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.evaluation.grid12 import grid12_targets, indices34
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.transforms import Array
from pipeline.montecarlo.stats import generators
from pipeline.rig.true_robot import ErrorSigmas, draw_puma_eps
from pipeline.robots import puma560

#: Configuration branch of the grid task for both controllers.
GRID_BRANCH = puma560.Branch(shoulder=1, elbow=1, wrist=1)


def design_joints(T: Array) -> Array:
    """Closed-form design inverse (m, 6), rad, of flange poses (m, 4, 4) on :data:`GRID_BRANCH`."""
    q, ok = puma560.inverse_kinematics(T)
    k = puma560.BRANCHES.index(GRID_BRANCH)
    if not ok[:, k].all():
        raise ArmsigError(
            "Monte-Carlo task pose out of the Puma design model's reach",
            expected="poses inside the workspace (Table 7-1 vertices are)",
            got=f"{int(np.sum(~ok[:, k].astype(bool)))} unreachable poses",
        )
    out: Array = q[:, k, :]
    return out


@cache
def grid_design_joints() -> Array:
    """Design-inverse joint readings (12, 6) of the Table 7-1 poses (rad), read-only."""
    out = design_joints(grid12_targets())
    out.setflags(write=False)
    return out


def puma_eps_batch(seeds: list[np.random.SeedSequence], sigmas: ErrorSigmas) -> Array:
    """ε of one robot per seed, shape (R, 39), math units."""
    return np.stack([draw_puma_eps(g, sigmas) for g in generators(seeds)])


def design_control_poses(eps: Array, q: Array) -> Array:
    """Flange poses (R, m, 4, 4) of robots ε (R, 39) at encoder readings q (m, 6)."""
    chain = puma560.simulator_chain(eps)  # links (R, 6, 4, 4), base (R, 4, 4)
    batched = SerialChain(
        links=chain.links[:, None], prismatic=chain.prismatic, base=chain.base[:, None]
    )
    return forward_kinematics(batched, q)


def design_indices(sigmas: ErrorSigmas, seeds: list[np.random.SeedSequence]) -> Array:
    """The 34 indices (R, 34) of design-model control for one robot per seed."""
    eps = puma_eps_batch(seeds, sigmas)
    return indices34(design_control_poses(eps, grid_design_joints()), grid12_targets())


def encoder_setting(sigma_e_deg: float, seeds: list[np.random.SeedSequence]) -> Array:
    """Section 7.4.1: σ_e swept, σ_p = 0.01 cm and σ_o = 0.01° (ERRATA.md)."""
    return design_indices(ErrorSigmas(0.01, 0.01, sigma_e_deg), seeds)


def machining_setting(sigma_po: float, seeds: list[np.random.SeedSequence]) -> Array:
    """Section 7.4.2: σ_p = σ_o (cm, deg) swept, σ_e = 0.1°."""
    return design_indices(ErrorSigmas(sigma_po, sigma_po, 0.1), seeds)
