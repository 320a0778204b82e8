"""The machine-readable summary of a session's evaluation (``pipeline evaluate --json``
and the evaluation report): every index of every task, design against signature."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.contract.evaluation import read_evaluation
from pipeline.control.controller import task_axes_for
from pipeline.evaluation.grid12 import CORNER_VERTICES
from pipeline.evaluation.score import AXIS_LETTERS, dropped_indices
from pipeline.evaluation.tasks import TASK_NAMES, reading_resolution
from pipeline.stages.runner import stage_path
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_table


def summarize(session_dir: str | Path) -> dict[str, Any]:
    """Machine-readable summary of the indices of a session's evaluation."""
    sdir = Path(session_dir)
    ind = read_table(stage_path(sdir, "evaluate_indices")).to_pylist()
    prog = read_table(stage_path(sdir, "evaluate_program"))
    rec = read_evaluation(sdir / "evaluation.mcap")
    taught = {r["task"] for r in rec.teach}
    axes = task_axes_for(session_robot(read_table(stage_path(sdir, "session"))))
    ok: dict[str, bool] = {}
    for t, o in zip(prog.column("task").to_pylist(), prog.column("ok").to_pylist(), strict=True):
        ok[t] = ok.get(t, True) and bool(o)
    tasks: dict[str, Any] = {}
    skipped: dict[str, str] = {}
    for name in TASK_NAMES:
        rows = [r for r in ind if r["task"] == name]
        if not rows:
            skipped[name] = (
                "not taught: the rig could not put the probe on its teach points"
                if name not in taught
                else "a controller has no valid solution (unreachable or outside the joint limits)"
                if not ok.get(name, True)
                else "not measured"
            )
            continue
        items = []
        for r in rows:
            u = r["unit"]
            d, sg = r[f"design_{u}"], r[f"signature_{u}"]
            res = reading_resolution(name, r["name"])
            # A signature reading within half a resolution step of zero reads as zero:
            # the factor is then only known to be at least |design| / resolution.
            bound = bool(res and abs(sg) < 0.5 * res)
            items.append(
                {
                    "name": r["name"],
                    "unit": u,
                    "signed": r["signed"],
                    "design": d,
                    "signature": sg,
                    "improvement": abs(d) / res if bound else r["improvement"],
                    "improvement_is_lower_bound": bound,
                }
            )
        imp = np.array([i["improvement"] for i in items], float)
        for i in items:  # JSON has no infinity: null means "signature error exactly 0"
            i["improvement"] = i["improvement"] if np.isfinite(i["improvement"]) else None
        median = float(np.median(imp))
        tasks[name] = {
            "indices": items,
            "median_improvement": median if np.isfinite(median) else None,
            "not_applicable": dropped_indices(name, axes),
        }
    out: dict[str, Any] = {
        "session": str(sdir),
        "rig": rec.description,
        "controlled": [("x", "y", "z", *("r" + a for a in AXIS_LETTERS))[a] for a in axes],
        "tasks": tasks,
        "skipped": skipped,
    }
    if "grid12" in tasks:
        rad = {i["name"]: i["signature"] for i in tasks["grid12"]["indices"]}
        out["grid12_signature_radial_cm"] = {
            str(v): rad[f"vertex{v}_radial_error_cm"] for v in CORNER_VERTICES
        }
    return out
