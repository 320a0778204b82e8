"""The identification report's validation section: the model's position error on
measured points (stage ``validation``; docs/import.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.evaluation.validation import position_errors

ROLE_TEXT = {
    "check": "validation configurations (not used by the fit)",
    "fit": "fit data (the tool measurement, the sweeps' end-effector points, the pose set)",
}


def validation_section(rows: list[dict[str, Any]] | None) -> str:
    """Mean, RMS and max position error per role, as measured and base-registered (cm);
    a session without the stage (sonic) or without points gets one line saying so."""
    head = "## Validation: model position error on measured points\n\n"
    if not rows:
        return head + "No measured tool-target points to compare (no `check` configurations)."
    body = [
        "| data | points | mean (cm) | RMS (cm) | max (cm) | registered mean | "
        "registered RMS | registered max |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for role, text in ROLE_TEXT.items():
        sel = [r for r in rows if r["role"] == role]
        if not sel:
            continue
        raw = np.array([r["error_cm"] for r in sel])
        reg_v = [r["registered_error_cm"] for r in sel]
        reg = None if any(v is None for v in reg_v) else np.array(reg_v, float)
        e = position_errors(raw, reg)
        regs = ["—"] * 3 if reg is None else [
            f"{v:.4g}" for v in (e.registered_mean_cm, e.registered_rms_cm, e.registered_max_cm)
        ]  # fmt: skip
        body.append(
            f"| {text} | {e.n} | {e.mean_cm:.4g} | {e.rms_cm:.4g} | {e.max_cm:.4g} | "
            + " | ".join(regs) + " |"
        )  # fmt: skip
    note = (
        "\n\nModel: the signature's forward kinematics with its tool at the recorded joint "
        "values. Registered: after the least-squares rigid motion of the model points onto "
        "the measured ones (the base's placement removed)."
    )
    return head + "\n".join(body) + note


def validation_rows(stage_file: Path) -> list[dict[str, Any]] | None:
    """The ``validation`` stage's rows, or None when the session has no such stage."""
    from pipeline.stages.tables import read_table

    return read_table(stage_file).to_pylist() if stage_file.is_file() else None
