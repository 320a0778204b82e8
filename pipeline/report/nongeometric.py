"""The identification report's section on the non-geometric signature (issue 27): how
``refine.nongeometric=auto`` chose the model (the candidates' cross-validation, issue
41), the terms fitted with their σ and |β|/σ, whether they paid off on the held-out
positions (the same positions held out of the rigid fit, stage ``holdout``'s
``rigid_error_cm``), the joint ranges the data covered and how uncertain the deflection
is outside them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.kinematics.nongeometric import KINDS, regressor
from pipeline.stages.refine import internal_factors, nongeometric_model, refine_summary

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


def choice_text(cv: dict[str, Any], table: Table) -> str:
    """The cross-validated choice of ``refine.nongeometric=auto`` (the refine summary's
    ``nongeometric.cv``): the reason, and per candidate its terms, CV held-out RMS, gains
    over the simpler candidates it nests ± their fold-to-fold spread, taken and why."""

    def gains(c: dict[str, Any]) -> str:
        return "; ".join(
            f"{g['gain_cm2']:.2g} ± {g['spread_cm2']:.2g} over {g['over']}"
            if g["gain_cm2"] is not None
            else f"none over {g['over']}"
            for g in c.get("gains", [])
        )

    rows = [
        [
            c["candidate"],
            c.get("terms", "–"),
            "–" if c.get("rms_cm") is None else f"{c['rms_cm']:.4g}",
            gains(c) or "–",
            "**yes**" if c["taken"] else "no",
            c["why"],
        ]
        for c in cv["candidates"]
    ]
    from pipeline.refine.model_choice import HARMONIC_EXTRAPOLATION

    spans = cv.get("harmonic_extrapolation", {})
    joints = ", ".join(
        f"{j} {v:.2g}" + ("" if v <= HARMONIC_EXTRAPOLATION else " (not a candidate)")
        for j, v in spans.items()
    )
    harmonics = (
        f"A joint's harmonic is a candidate only when its readings span enough of a turn: "
        f"its variance anywhere on the turn at most {HARMONIC_EXTRAPOLATION:g}× that at the "
        f"readings ({joints}).\n\n"
        if spans
        else ""
    )
    sub = cv.get("positions")
    on = (
        f" on evenly spaced poses ({sub['chosen_on']:,} of {sub['of']:,} positions; the "
        "chosen one then fitted to all)"
        if sub
        else ""
    )
    return (
        f"**Model: {cv['why']}.** `refine.nongeometric=auto` fitted each candidate and "
        f"scored it by {cv['folds']}-fold cross-validation over blocks of the measurement "
        f"order{on}; a candidate is taken only when it beats every simpler one it nests by more "
        "than the fold-to-fold spread of the gain (paired per-fold differences of the "
        "held-out mean squared error, mean > 0 and > their standard deviation), and of "
        "those the lowest CV error wins (docs/nongeometric.md).\n\n"
        + table(
            ["candidate", "terms", "CV held-out RMS (cm)", "gain (cm²) ± spread", "taken", "why"],
            rows,
        )
        + "\n\n"
        + harmonics
    )


def nongeometric_section(
    refine: pa.Table, holdout: pa.Table, readings_deg: np.ndarray, robot: Any, table: Table
) -> str:
    """The section; ``readings_deg`` (m, n): the joint readings of the fitted positions
    (deg / cm), ``table``: the report's Markdown table writer."""
    from pipeline.units import joints_to_internal

    head = "## Non-geometric signature: compliance and joint-angle errors\n\n"
    cv = refine_summary(refine).get("nongeometric", {}).get("cv")
    text = head + ("" if cv is None else choice_text(cv, table))
    rows = [r for r in refine.to_pylist() if r["group"] in KINDS]
    if not rows:
        return text + "The signature is the rigid chain: no non-geometric term.\n"
    text += (
        "Joint deflections the rigid chain leaves out, fitted with it (docs/nongeometric.md): "
        "`compliance.j<j>.link<k>` deflects joint j by its value × the lever of a unit "
        "weight at link k's frame origin about joint j's axis (design chain, gravity −z of "
        "its base); `harmonic.j<j>.cos|sin` by its value × cos|sin of joint j's reading. "
        "|β|/σ: how many standard deviations the value is from zero (below 2 the data "
        "hardly tell it from zero; a term the fit held has σ 0).\n\n"
    )
    text += table(
        ["term", "unit", "fitted", "σ", "\\|β\\|/σ"],
        [
            [
                r["name"],
                r["unit"],
                f"{r['value']:.4g}",
                f"{r['sigma']:.2g}",
                f"{abs(r['value']) / r['sigma']:.1f}" if r["sigma"] > 0 else "held",
            ]
            for r in rows
        ],
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
            "(`pipeline validate --against`)."
        )
    text += "\n\n"
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
