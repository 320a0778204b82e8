"""The machine-readable summary of a session's evaluation (``pipeline evaluate --json``
and the evaluation report): every index of every task, design against signature, and the
design controller driven to compensated targets beside them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.contract.evaluation import read_evaluation
from pipeline.control.controller import task_axes_for
from pipeline.evaluation.grid12 import CORNER_VERTICES
from pipeline.evaluation.indices import improvement
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
        comp_run = all(r.get(f"compensated_{r['unit']}") is not None for r in rows)
        for r in rows:
            u = r["unit"]
            d, sg, comp = r[f"design_{u}"], r[f"signature_{u}"], r.get(f"compensated_{u}")
            res = reading_resolution(name, r["name"])
            imp, bound = _factor(d, sg, r["improvement"], res)
            item = {
                "name": r["name"],
                "unit": u,
                "signed": r["signed"],
                "design": d,
                "signature": sg,
                "improvement": imp,
                "improvement_is_lower_bound": bound,
                # The design controller driven to compensated targets (null: not run).
                "compensated": comp,
            }
            if comp_run:
                factor = float(improvement(np.array([d]), np.array([comp]))[0])
                ci, cb = _factor(d, comp, factor, res)
                item["improvement_compensated"] = ci
                item["improvement_compensated_is_lower_bound"] = cb
            items.append(item)
        tasks[name] = {
            "indices": items,
            "median_improvement": _median(items, "improvement"),
            # |design| / |compensated| over the indices; absent: no compensated run.
            **(
                {"median_improvement_compensated": _median(items, "improvement_compensated")}
                if comp_run
                else {}
            ),  # fmt: skip
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


def _factor(design: float, value: float, factor: float, res: float | None) -> tuple[float, bool]:
    """The improvement factor ``|design| / |value|`` and whether it is a lower bound: a
    reading within half a resolution step of zero reads as zero, and the factor is then only
    known to be at least ``|design| / resolution``."""
    bound = bool(res and abs(value) < 0.5 * res)
    return (abs(design) / res if bound and res else factor), bound


def _median(items: list[dict[str, Any]], key: str) -> float | None:
    """The median of ``key`` over the items; each item's infinite factor (an error exactly 0)
    and the median's become null, as JSON has no infinity."""
    values = np.array([i[key] for i in items], float)
    for i in items:
        i[key] = i[key] if np.isfinite(i[key]) else None
    median = float(np.median(values))
    return median if np.isfinite(median) else None
