"""The identification report's section on the non-geometric signature (issue 27): the
terms fitted with their σ, whether they paid off on the held-out positions (the same
positions held out of the rigid fit, stage ``holdout``'s ``rigid_error_cm``), the joint
ranges the data covered and how uncertain the deflection is outside them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.kinematics.nongeometric import KINDS, regressor
from pipeline.stages.refine import internal_factors, nongeometric_model

Table = Callable[[Sequence[str], Sequence[Sequence[Any]]], str]
#: Random configurations within the limits the deflection's uncertainty is taken over.
CONFIGURATIONS = 2000


def deflection_sigma_deg(refine: pa.Table, robot: Any, q: np.ndarray) -> np.ndarray:
    """σ (deg) of every joint's deflection ``Φ(q)β`` at readings ``q`` (m, n), rad / cm,
    from the covariance of the fitted coefficients, shape (m, n)."""
    ng = nongeometric_model(refine, robot)
    if ng is None:
        return np.zeros(q.shape)
    rows = np.flatnonzero(np.isin(refine.column("group").to_pylist(), KINDS))
    f = internal_factors(refine)[rows]
    cov = np.array(refine.column("covariance").to_pylist(), float)[np.ix_(rows, rows)]
    cov *= np.outer(f, f)
    Phi = regressor(ng.terms, ng.design, q)  # (m, n, size)
    return np.degrees(np.sqrt(np.einsum("mns,st,mnt->mn", Phi, cov, Phi)))


def nongeometric_section(
    refine: pa.Table, holdout: pa.Table, readings_deg: np.ndarray, robot: Any, table: Table
) -> str:
    """The section; ``readings_deg`` (m, n): the joint readings of the fitted positions
    (deg / cm), ``table``: the report's Markdown table writer."""
    from pipeline.units import joints_to_internal

    head = "## Non-geometric signature: compliance and joint-angle errors\n\n"
    rows = [r for r in refine.to_pylist() if r["group"] in KINDS]
    text = head + (
        "Joint deflections the rigid chain leaves out, fitted with it (docs/nongeometric.md): "
        "`compliance.j<j>.link<k>` deflects joint j by its value × the lever of a unit "
        "weight at link k's frame origin about joint j's axis (design chain, gravity −z of "
        "its base); `harmonic.j<j>.cos|sin` by its value × cos|sin of joint j's reading.\n\n"
    )
    text += table(
        ["term", "unit", "fitted", "σ"],
        [[r["name"], r["unit"], f"{r['value']:.4g}", f"{r['sigma']:.2g}"] for r in rows],
    )
    err = holdout.column("error_cm").to_numpy(zero_copy_only=False)
    rigid = holdout.column("rigid_error_cm").to_numpy(zero_copy_only=False)
    if len(err) and np.isfinite(rigid).all():
        with_terms, without = (float(np.sqrt(np.mean(v**2))) for v in (err, rigid))
        verdict = "paid off" if with_terms < without else "did not pay off"
        text += (
            f"\n\nHeld-out error on the same {len(err)} positions: **{with_terms:.4g} cm RMS "
            f"with the terms, {without:.4g} cm without** (the rigid chain fitted to the same "
            f"data): the terms {verdict} here. Held-out error on the data a fit saw is not "
            "enough to choose a model: judge it on another series too "
            "(`pipeline validate --against`).\n\n"
        )
    lim = robot.limits
    lo, hi = readings_deg.min(axis=0), readings_deg.max(axis=0)
    q_data = joints_to_internal(readings_deg, robot.prismatic)
    q_all = robot.random_configurations(CONFIGURATIONS, 0)
    inside = deflection_sigma_deg(refine, robot, q_data).max(axis=0)
    everywhere = deflection_sigma_deg(refine, robot, q_all).max(axis=0)
    text += (
        "Joint ranges the fitted positions covered, and the deflection's largest σ there "
        f"and over {CONFIGURATIONS} configurations anywhere within the limits: a term "
        "extrapolates where the second is much larger than the first.\n\n"
    )
    text += table(
        ["joint", "covered", "limits", "σ deflection covered (deg)", "σ anywhere (deg)"],
        [
            [
                j.name,
                f"{lo[i]:.1f} to {hi[i]:.1f}",
                f"{lim[i, 0]:g} to {lim[i, 1]:g}",
                f"{inside[i]:.2g}",
                f"{everywhere[i]:.2g}",
            ]  # fmt: skip
            for i, j in enumerate(robot.joints)
        ],
    )
    return text
