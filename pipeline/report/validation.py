"""The identification report's validation section: the model's position error on
measured points (stage ``validation``; docs/import.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.evaluation.validation import position_errors
from pipeline.sensor.range_rows import unique_rows

ROLE_TEXT = {
    "check": "validation configurations (not used by the fit)",
    "fit": "fit data (the tool measurement, the sweeps' end-effector points, the pose set)",
}


def role_errors(table: pa.Table | None) -> dict[str, dict[str, Any]]:
    """Per role of the ``validation`` table: the signature's position errors as measured
    and base-registered, and the registered design model's RMS beside them (cm; None
    where the rows have none): the numbers of the report's table, ``identify --json`` and
    ``fleet``. By columns (a million-row pose set's rows as Python dicts took GBs)."""
    out: dict[str, dict[str, Any]] = {}
    if table is None:
        return out
    import pyarrow.compute as pc

    for role in ROLE_TEXT:
        sel = table.filter(pc.equal(table.column("role"), role))
        if not sel.num_rows:
            continue
        raw = sel.column("error_cm").to_numpy(zero_copy_only=False).astype(float)
        reg = _floats(sel, "registered_error_cm")
        design = _floats(sel, "design_error_cm") if "design_error_cm" in sel.column_names else None
        out[role] = {
            **position_errors(raw, reg).to_dict(),
            "design_registered_rms_cm": (
                None if design is None else float(np.sqrt(np.mean(design**2)))
            ),
        }
    return out


def _floats(table: pa.Table, name: str) -> np.ndarray | None:
    """A column of floats, None when any row has none (null)."""
    col = table.column(name)
    return None if col.null_count else col.to_numpy().astype(float)


def validation_section(table: pa.Table | None, joints: pa.Table | None = None) -> str:
    """Mean, RMS and max position error per role, as measured and base-registered (cm),
    and the registered design model's RMS beside them; a session without the stage (sonic)
    or without points gets one line saying so."""
    head = "## Validation: model position error on measured points\n\n"
    if table is None or not table.num_rows:
        return head + "No measured tool-target points to compare (no `check` configurations)."
    body = [
        "| data | points | mean (cm) | RMS (cm) | max (cm) | registered mean | "
        "registered RMS | registered max | design model, registered RMS |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for role, e in role_errors(table).items():
        keys = ("registered_mean_cm", "registered_rms_cm", "registered_max_cm",
                "design_registered_rms_cm")  # fmt: skip
        cells = ["—" if e.get(k) is None else f"{e[k]:.4g}" for k in keys]
        body.append(
            f"| {ROLE_TEXT[role]} | {e['n']} | {e['mean_cm']:.4g} | {e['rms_cm']:.4g} | "
            f"{e['max_cm']:.4g} | " + " | ".join(cells) + " |"
        )  # fmt: skip
    note = (
        "\n\nModel: the signature's forward kinematics with its tool at the recorded joint "
        "values. Registered: after the least-squares rigid motion of the model points onto "
        "the measured ones (the base's placement removed). Design model, registered: the "
        "design chain with its base and tool point fitted to the fit points, the error the "
        "arm makes uncalibrated in a registered cell (the before of the before/after)."
    )
    return head + "\n".join(body) + note + held_out_text(table) + drift_text(joints)


def drift_text(joints: pa.Table | None) -> str:
    """The tracker's drift by fixed targets (issue 42: ``joints`` table,
    ``tracker_drift_cm`` per configuration): median and maximum before the correction,
    and the residual after it (none: the correction was not applied); empty without
    fixed targets."""
    if joints is None or "tracker_drift_cm" not in joints.column_names:
        return ""
    import pyarrow.compute as pc

    drifted = joints.filter(pc.is_valid(joints.column("tracker_drift_cm")))
    sweep, step = (drifted.column(c).to_numpy().astype(np.int64) for c in ("sweep", "step"))
    first = np.unique(unique_rows(np.stack([sweep, step], axis=1))[1], return_index=True)[1]
    per = drifted.take(pa.array(np.sort(first)))  # one row per configuration
    if not per.num_rows:
        return ""
    drift = per.column("tracker_drift_cm").to_numpy()
    res = per.column("tracker_residual_cm").drop_null().to_numpy()
    after = "" if not len(res) else (
        f"; after registering each pose by them, median {np.median(res):.3g} cm, max "
        f"{res.max():.3g} cm")  # fmt: skip
    return (
        f"\n\nTracker drift by the fixed targets ({per.num_rows} configurations, RMS distance "
        f"of their readings from their reference, `joints` table `tracker_drift_cm`): median "
        f"{np.median(drift):.3g} cm, max {drift.max():.3g} cm before the correction{after}. "
        + (
            "The points above are the registered ones."
            if len(res)
            else 'Not corrected (no drift beyond their noise, or fixed_correction = "never"): '
            "the points above are as measured."
        )  # fmt: skip
    )


def held_out_text(table: pa.Table) -> str:
    """Which rows were held out (role ``check``), by their source file and lines (issue
    42): "region_3.csv lines 2-7, 9"; empty when none, or none records its source."""
    if "source_file" not in table.column_names:
        return ""
    import pyarrow.compute as pc

    check = table.filter(pc.equal(table.column("role"), "check"))
    lines: dict[str, list[int]] = {}
    for f, ln in zip(check.column("source_file").to_pylist(),
                     check.column("source_line").to_pylist(), strict=True):  # fmt: skip
        if f:
            lines.setdefault(f, []).append(int(ln or 0))
    if not lines:
        return ""
    parts = [f"{f} {_ranges(sorted(v))}" for f, v in lines.items()]
    n = sum(len(v) for v in lines.values())
    return f"\n\nHeld out ({n} rows, by source file and line): " + "; ".join(parts) + "."


def _ranges(values: list[int]) -> str:
    """Sorted line numbers as runs: [2, 3, 4, 9] -> "lines 2-4, 9" (0: no line)."""
    if values and values[0] == 0:
        return f"({len(values)} entries)"
    runs: list[list[int]] = []
    for v in values:
        if runs and v == runs[-1][1] + 1:
            runs[-1][1] = v
        else:
            runs.append([v, v])
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs)
    return ("line " if len(values) == 1 else "lines ") + text


def validation_table(stage_file: Path) -> pa.Table | None:
    """The ``validation`` stage's table, or None when the session has no such stage."""
    from pipeline.stages.tables import read_table

    return read_table(stage_file) if stage_file.is_file() else None
