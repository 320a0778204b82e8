"""The report's verdict section (at its top) and the figure of the predicted tool error."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.report.figures import few_ticks, save_png

#: Rows of the verdict's numbers table: column, label, format.
_NUMBERS = (
    ("predicted_rms_cm", "predicted RMS tool error over the workspace (cm)", ".4f"),
    ("predicted_parameters_rms_cm", "its parameters' part, aligned (cm)", ".4f"),
    ("unmodelled_rms_cm", "its unmodelled part: the residual beyond the noise (cm)", ".4f"),
    ("predicted_limit_cm", "its limit: max_predicted_rms_reach × the design's reach (cm)", ".4g"),
    ("predicted_p95_cm", "95th percentile over the workspace (cm)", ".4f"),
    ("predicted_max95_cm", "95 % bound of the largest parameters' error (cm)", ".4f"),
    ("holdout_rms_cm", "held-out RMS position error (cm)", ".4f"),
    ("holdout_p95_cm", "held-out 95th percentile (cm)", ".4f"),
    ("holdout_expected_rms_cm", "its prediction (cm)", ".4f"),
    ("holdout_design_rms_cm", "the registered design model at the same points (cm)", ".4f"),
    ("gain", "measured gain: design over signature, held out (×)", ".3g"),
    ("worse_sigmas", "signature's squared error minus the design's (standard errors)", ".3g"),
    ("design_misfit_rms_cm", "design model vs signature, RMS after alignment (cm)", ".4f"),
    ("design_reach_cm", "the design's reach, the scale of that misfit (cm)", ".4g"),
    ("misfit_sigmas", "that misfit in the signature's predicted errors (σ; no rule)", ".3g"),
    ("chi2_per_dof", "χ²/dof, sensor self-calibrated", ".3f"),
    ("chi2_recorded_per_dof", "χ²/dof, sensor as recorded", ".3f"),
    ("stated_sigma_cm", "the points' stated σ, median (cm)", ".4g"),
    ("max_bias_sigmas", "largest microphone range bias (σ)", ".2f"),
    ("max_mic_sigmas", "largest microphone move (σ)", ".2f"),
)


def error_map(uncertainty: pa.Table, path: Path) -> Path:
    """Where in the workspace the predicted (aligned) tool error is large: the tool
    positions of the random configurations, top (x-y) and side (x-z) views, coloured by
    the predicted error."""
    from matplotlib.figure import Figure

    xyz = np.stack([uncertainty.column(f"{a}_cm").to_numpy() for a in "xyz"], axis=1)
    s = uncertainty.column("sigma_position_aligned_cm").to_numpy()
    order = np.argsort(s)  # largest drawn last, on top
    fig = Figure(figsize=(9.0, 3.8))
    fig.subplots_adjust(left=0.08, right=0.88, bottom=0.14, top=0.88, wspace=0.3)
    axes = fig.subplots(1, 2)
    for ax, (i, j) in zip(axes, ((0, 1), (0, 2)), strict=True):
        sc = ax.scatter(xyz[order, i], xyz[order, j], c=s[order], s=6, cmap="viridis")
        ax.set_xlabel(f"{'xyz'[i]} (cm, sensor frame)")
        ax.set_ylabel(f"{'xyz'[j]} (cm)")
        ax.set_aspect("equal", adjustable="datalim")
        few_ticks(ax)
    fig.suptitle("Predicted tool position error (1σ RMS, after base/tool alignment)")
    cax = fig.add_axes((0.9, 0.14, 0.02, 0.74))
    fig.colorbar(sc, cax=cax, label="cm")
    return save_png(fig, path)


def verdict_section(verdict: dict[str, Any], figure: Path | None) -> str:
    """``## Verdict``: the line, one bullet per reason, the numbers, the error map."""
    out = [f"## Verdict: {verdict['verdict']}", f"**{verdict['line']}**"]
    by = verdict.get("decided_by") or "rules"
    out.append(
        "Decided by the thresholds' rules (below)." if by == "rules" else
        f"Decided by the stated requirement (`verdict.{by}`): the held-out and predicted errors "
        "against it; the χ², held-out-ratio, predicted-limit and held-parameter rules not applied."
    )  # fmt: skip
    if verdict["reasons"]:
        out.append("\n".join(f"- {r}" for r in verdict["reasons"]))
    rows = [
        f"| {label} | {format(verdict[k], spec)} |"
        for k, label, spec in _NUMBERS
        if verdict.get(k) is not None
    ]
    if rows:
        out.append("\n".join(["| quantity | value |", "|---|---|", *rows]))
    out.append(
        "Thresholds and what each rule means: docs/verdict.md "
        "(`--param verdict.NAME=VALUE` sets them)."
    )
    if figure is not None:
        out.append(f"![predicted tool error over the workspace]({figure.name})")
    return "\n\n".join(out)
