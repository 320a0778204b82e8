"""The identification report's pose-set section (issue 26): what a session of random
whole-arm poses identified, and how well.

A pose set has no circles to report (Tables 6-4, 6-5 and Figures 6-11 to 6-13 are about
joint sweeps). Instead: what the data could identify (stage ``refine``'s summary: poses,
parameters, rank, the parameters held at the design and why, condition number,
observability index, correlations), the fitted parameters with their σ, and the fit's
residual at every pose against the pose's reach (figure ``pose_residuals.png``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.kinematics.nongeometric import KINDS, Terms
from pipeline.stages.refine import refine_summary, refined_x
from pipeline.sweeps import POSES_SWEEP

Row = dict[str, Any]
Table = Callable[[Sequence[str], Sequence[Sequence[Any]]], str]


def pose_residuals(tables: dict[str, pa.Table]) -> tuple[np.ndarray, np.ndarray]:
    """Per measured point of the pose set: the fit's residual |measured − signature| (cm)
    and its reach, the distance from joint 1's axis (cm). Joined by (sweep, step,
    target) through the refinement's own model (:mod:`pipeline.stages.refine_problem`)."""
    import pyarrow.compute as pc

    from pipeline.stages.positions import positions
    from pipeline.stages.refine_problem import model_for_keys

    pos = tables["positions"]
    rows = pos.filter(pc.equal(pos.column("sweep"), POSES_SWEEP))
    rows = rows.filter(pa.array(np.isfinite(positions(rows)).all(axis=1)))
    if rows.num_rows == 0:
        return np.zeros(0), np.zeros(0)
    keys = rows.select(["sweep", "step", "target"])
    refine = tables["refine"]
    groups = refine.column("group").to_pylist()
    terms = Terms.from_names([n for n, g in zip(refine.column("name").to_pylist(), groups,
                                                strict=True) if g in KINDS])  # fmt: skip
    model = model_for_keys(keys, tables["session"], tables["joints"], tables["frames"],
                           "tool_rotation" in groups, terms)  # fmt: skip
    x = _model_x(refine, model.n_params - terms.size, terms.size)
    m = positions(rows)
    axis = model.frames(x)[0]  # S̄_0: joint 1's axis is its Z
    v = m - axis[:3, 3]
    reach = np.linalg.norm(v - np.outer(v @ axis[:3, 2], axis[:3, 2]), axis=1)
    return np.linalg.norm(m - model.positions(x), axis=1), reach


def _model_x(refine: pa.Table, n_rigid: int, n_terms: int) -> np.ndarray:
    """The chain model's ``x`` from a ``refine`` table: its first ``n_rigid`` parameters
    (axes, points, tool rotation: the points of other targets come after the tool's in
    the table as in the model) and the ``n_terms`` non-geometric ones, which follow the
    sensor's in the table."""
    x = refined_x(refine)
    groups = np.array(refine.column("group").to_pylist())
    terms = x[np.isin(groups, KINDS)]
    assert len(terms) == n_terms
    return np.concatenate([x[:n_rigid], terms])


def residual_figure(residual: np.ndarray, reach: np.ndarray, path: Path) -> Path:
    """Residual (cm) against reach (cm), one dot per measured point."""
    from matplotlib.figure import Figure

    from pipeline.report.figures import save_png

    fig = Figure(figsize=(6.0, 3.5))
    ax = fig.add_subplot()
    ax.plot(reach, residual, ".", ms=4)
    ax.set_xlabel("reach: distance from joint 1's axis (cm)")
    ax.set_ylabel("|measured − signature| (cm)")
    ax.set_title("Pose set: fit residual per measured point")
    ax.grid(alpha=0.3)
    return save_png(fig, path)


def pose_set_section(tables: dict[str, pa.Table], out: Path, table: Table) -> str:
    """The section (module docstring); ``table``: the report's Markdown table writer."""
    summ = refine_summary(tables["refine"])
    ident = summ.get("identifiability")
    head = "## Pose set: identification from whole-arm poses\n\n"
    if not ident:
        return head + "The refinement did not run (`refine.enabled=false`): nothing to report."
    held = ident["held"]
    facts = [
        ["poses", ident["n_poses"]],
        ["measured points", ident["n_points"]],
        ["kinematic parameters", ident["n_params"]],
        ["identified (rank)", ident["rank"]],
        ["poses the identified parameters need at least", ident["poses_needed"]],
        ["condition number (tolerance-scaled)", f"{ident['condition']:.3g}"],
        ["observability index O₁", f"{ident['observability_index']:.3g}"],
    ]
    text = head + table(["quantity", "value"], facts)
    tol = ident["tolerance"]
    text += (
        f"\n\nParameters are scaled by a design tolerance ({tol['cm']:g} cm, {tol['deg']:g}°) "
        "and ordered by QR with column pivoting of the whitened Jacobian; a parameter is "
        "held at the design when the data cannot see it (*structural*) or a tolerance-sized "
        "error in it moves the residuals by less than one σ (*below noise*); "
        'docs/refine.md, "Pose sets".\n\n'
    )
    if held:
        text += "Held at the design value (not identified by these data):\n\n" + table(
            ["parameter", "why", "σ per tolerance"],
            [[h["name"], h["why"], f"{h['sigmas_per_tolerance']:.2g}"] for h in held],
        )
    else:
        text += "Every parameter is identified."
    corr = ident["correlated"]
    text += "\n\n" + (
        table(
            ["parameter", "parameter", "correlation"],
            [[c["a"], c["b"], f"{c['rho']:+.3f}"] for c in corr],
        )  # fmt: skip
        if corr
        else "No two identified parameters correlate above 0.95."
    )
    text += "\n\n" + _parameter_table(tables["refine"], {h["name"] for h in held}, table)
    residual, reach = pose_residuals(tables)
    if len(residual):
        fig = residual_figure(residual, reach, out / "pose_residuals.png")
        rms = float(np.sqrt(np.mean(residual**2)))
        text += (
            f"\n\nFit residual over the {len(residual)} measured points of the pose set: "
            f"RMS {rms:.4g} cm, max {residual.max():.4g} cm (χ²/dof "
            f"{summ['noise_scale'] ** 2:.3g}).\n\n![fit residual against reach]({fig.name})"
        )
    return text


def _parameter_table(refine: pa.Table, held: set[str], table: Table) -> str:
    rows = []
    for r in refine.to_pylist():
        if r["group"] not in ("axis", "point"):
            continue
        note = "held" if r["name"] in held else ""
        rows.append([r["name"], r["unit"], f"{r['start']:.6g}", f"{r['value']:.6g}",
                     f"{r['value'] - r['start']:+.4g}", f"{r['sigma']:.2g}", note])  # fmt: skip
    head = ["parameter", "unit", "design start", "fitted", "change", "σ", ""]
    return (
        "Fitted parameters (joint axis lines as moves of the design frames, "
        "docs/refine.md; points at q̄ˢ in the sensor frame):\n\n" + table(head, rows)
    )
