"""Closed-form Puma 560 design inverse wrapped for the numerical controllers (Chapter 5).

Supplies the initial estimate of Newton-Raphson and the design inverse
``F_d⁻¹`` of the Jacobi iterative method (5.8), on a requested branch.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import KinematicsError
from pipeline.kinematics.chain import soa_blocks
from pipeline.kinematics.ik import DesignInverse
from pipeline.kinematics.transforms import Array, ArrayLike, invert_transform
from pipeline.robots import puma560
from pipeline.robots.puma560 import Branch

#: Clamp margins of :func:`puma_design_inverse`: a pose the design model cannot
#: reach is pulled onto the workspace with the elbow 1° short of fully stretched
#: (or folded) and the wrist centre at least 1 cm off the shoulder cylinder
#: (r = 0), so the configuration handed to the solvers is not exactly singular.
#: Both are far below the ~12° elbow / ~1 cm shoulder mismatch that 0.5 cm of
#: model error causes next to those boundaries, and far above round-off.
PUMA_ELBOW_MARGIN_RAD = float(np.deg2rad(1.0))
PUMA_SHOULDER_MARGIN_CM = 1.0

#: Clamp margins for the Jacobi iteration's design inverse (5.8). Its iterates
#: ``F_d(q) F_s(q)⁻¹ T*`` leave the design workspace when the solution lies
#: within the signature/design mismatch of a boundary; a 1° or 1 cm margin then
#: pins them short of solutions that sit closer to the boundary (measured: 0.23 %
#: of random robot3 targets). 0.01° and 0.01 cm are below the ~0.05 cm model
#: mismatch, so only the unreachable part of an iterate is cut, and still far
#: above round-off. The Jacobi iteration needs no Jacobian, so the near-singular
#: configurations this produces do no harm there.
JACOBI_ELBOW_MARGIN_RAD = float(np.deg2rad(0.01))
JACOBI_SHOULDER_MARGIN_CM = 0.01


def _puma_clamp(Tw: Array, elbow_margin: float, shoulder_margin: float) -> Array:
    """Move the wrist centre of flange poses (k, 4, 4) into the Puma design workspace.

    ``Tw`` are flange poses in D-H frame 0. Uses the design geometry of
    :func:`pipeline.robots.puma560.inverse_kinematics` (wrist centre ``p − d6·a``;
    shoulder radius ``r² = px² + py² − d3²``; elbow
    ``K = (r² + pz² − d4² − a3² − a2²)/(2 a2)`` with ``|K| ≤ ρ = √(d4² + a3²)``).
    ``(r, pz)`` is scaled about the shoulder until ``|K| = ρ cos(margin)``; the
    orientation is unchanged.
    """
    d1, d3, _, d4, _, _ = puma560.DESIGN_D_CM
    a2, a3 = puma560.DESIGN_A_CM[1], puma560.DESIGN_A_CM[2]
    _, wc = puma560.flange_and_wrist_centre(Tw)
    px, py, pz = wc[:, 0], wc[:, 1], wc[:, 2] - d1
    rho2 = d4**2 + a3**2
    r = np.sqrt(np.maximum(px**2 + py**2 - d3**2, shoulder_margin**2))
    D2 = r**2 + pz**2
    K_lim = np.sqrt(rho2) * np.cos(elbow_margin)
    K = np.clip((D2 - rho2 - a2**2) / (2.0 * a2), -K_lim, K_lim)
    D2_new = rho2 + a2**2 + 2.0 * a2 * K
    # D2 > 0 always (r ≥ the shoulder margin); the scale keeps the elevation angle.
    scale = np.sqrt(D2_new / D2)
    r_new, pz_new = r * scale, pz * scale
    rad = np.hypot(px, py)
    ux = np.where(rad > 0.0, px / np.where(rad > 0.0, rad, 1.0), 1.0)
    uy = np.where(rad > 0.0, py / np.where(rad > 0.0, rad, 1.0), 0.0)
    R_new = np.sqrt(r_new**2 + d3**2)
    wc_new = np.stack([ux * R_new, uy * R_new, pz_new + d1], axis=-1)
    out = Tw.copy()
    out[:, :3, 3] += wc_new - wc
    return out


def puma_design_inverse(
    branch: Branch | None = None,
    tool: ArrayLike | None = None,
    base: ArrayLike | None = None,
    clamp: bool = True,
    elbow_margin_rad: float = PUMA_ELBOW_MARGIN_RAD,
    shoulder_margin_cm: float = PUMA_SHOULDER_MARGIN_CM,
) -> DesignInverse:
    """Closed-form Puma 560 design inverse (Appendix B.2) for :func:`jacobi_iterative`.

    Also the initial estimate of both solvers (Section 5.2):
    ``q0 = puma_design_inverse(branch)(T_target, q_ref)``.

    Parameters
    ----------
    branch : pipeline.robots.puma560.Branch or None
        Fixed configuration branch for every target. ``None`` uses, row by row,
        the branch of ``q_near`` (:func:`pipeline.robots.puma560.branch_of`);
        since the closed form returns solutions on the branch it is asked for,
        this keeps each target on the branch of its ``q0``.
    tool, base : array_like, shape (4, 4), optional
        Passed to :func:`pipeline.robots.puma560.inverse_kinematics` (flange to
        tool, world to D-H frame 0); identity for the built-in design chain.
    clamp : bool
        Where the design model cannot reach a pose on the branch, invert the
        pose pulled onto its workspace instead (elbow 1° short of stretched or
        folded, see :data:`PUMA_ELBOW_MARGIN_RAD`) rather than returning NaN.
        Targets near the workspace boundary that the signature reaches but the
        design model does not then still get a start and Jacobi iterates.
    elbow_margin_rad, shoulder_margin_cm : float
        Clamp margins: :data:`PUMA_ELBOW_MARGIN_RAD` / :data:`PUMA_SHOULDER_MARGIN_CM`
        for an initial estimate, :data:`JACOBI_ELBOW_MARGIN_RAD` /
        :data:`JACOBI_SHOULDER_MARGIN_CM` inside the Jacobi iteration.

    Returns
    -------
    callable
        ``(T (k, 4, 4), q_near (k, 6)) -> q (k, 6)`` in radians: the solution on
        the branch, unwrapped to the 2π class nearest to ``q_near`` (so joints
        whose travel exceeds ±180° do not jump); at a wrist singularity θ4 is
        kept from ``q_near`` and θ6 takes the rest. NaN rows where the design
        model cannot reach ``T`` (only with ``clamp=False``).
    """
    if branch is not None and not isinstance(branch, puma560.Branch):
        raise KinematicsError("bad branch", expected="puma560.Branch or None", got=repr(branch))
    table = np.array([[b.shoulder, b.elbow, b.wrist] for b in puma560.BRANCHES])
    wanted = None if branch is None else (branch,)
    # Targets are mapped to flange poses in D-H frame 0 once: base⁻¹ · T · tool⁻¹.
    base_inv = None if base is None else invert_transform(base)
    tool_inv = None if tool is None else invert_transform(tool)

    def inverse(T: Array, q_near: Array) -> Array:
        Tw = np.asarray(T, float)
        q_near = np.asarray(q_near, float)
        blocks = soa_blocks(len(Tw))
        if len(blocks) > 1:  # in cache-sized blocks (as the forward kinematics)
            return np.concatenate([inverse(Tw[b], q_near[b]) for b in blocks])
        if base_inv is not None:
            Tw = base_inv @ Tw
        if tool_inv is not None:
            Tw = Tw @ tool_inv
        sols, ok = puma560.inverse_kinematics(Tw, branches=wanted)
        if clamp and np.count_nonzero(ok) < ok.size:
            # Reachability does not depend on the branch for the Puma (the wrist
            # centre's distances decide it), so clamp whole rows.
            out = np.flatnonzero(~ok.all(axis=-1))
            sols[out], ok[out] = puma560.inverse_kinematics(
                _puma_clamp(Tw[out], elbow_margin_rad, shoulder_margin_cm), branches=wanted
            )
        if wanted is None:
            flags = puma560.branch_of(q_near)
            col = np.argmax(np.all(flags[:, None, :] == table[None], axis=-1), axis=-1)
            rows = np.arange(len(col))
            q, reach = sols[rows, col], ok[rows, col]
        else:
            q, reach = sols[:, 0], ok[:, 0]  # the one branch computed
        unreached = np.count_nonzero(reach) < reach.size
        if unreached:
            q = np.where(reach[:, None], q, q_near)  # keep NaN out of the arithmetic below
        # Wrist singular: inverse_kinematics set θ4 = 0; θ4 + θ6 (cos θ5 > 0) or
        # θ6 − θ4 (cos θ5 < 0) is what the pose fixes. Keep θ4 from q_near.
        sing = reach & (np.abs(np.sin(q[:, 4])) < puma560.WRIST_SINGULAR_TOL)
        if np.count_nonzero(sing):
            t4 = q_near[:, 3]
            t6 = np.where(np.cos(q[:, 4]) > 0, q[:, 5] + q[:, 3] - t4, q[:, 5] - q[:, 3] + t4)
            q[:, 3] = np.where(sing, t4, q[:, 3])
            q[:, 5] = np.where(sing, t6, q[:, 5])
        q = q_near + puma560.wrap_angle(q - q_near)  # nearest 2π class
        if unreached:
            q[~reach] = np.nan
        return q

    return inverse
