"""Stage ``evaluate_indices``: the performance indices of every measured task, each
controller (design, signature, compensated), and the improvement factor of the signature
over the design model (Tables 6-6 to 6-11, Section 7.2.1)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.control.controller import task_axes_for
from pipeline.evaluation.indices import improvement
from pipeline.evaluation.score import task_indices
from pipeline.evaluation.tasks import tasks_for
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.evaluate_program import nominal_tool
from pipeline.stages.session import session_robot


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    meas = inputs["evaluate_measurements"]
    measured = set(meas.column("task").to_pylist())
    robot = session_robot(inputs["session"])
    cols: dict[str, list[Any]] = {
        k: [] for k in ("task", "index", "name", "unit", "signed", "d", "s", "c")
    }
    for task in tasks_for(robot, nominal_tool(inputs["session"])):
        if task.name not in measured:
            continue
        names, values = task_indices(task, meas, inputs["evaluate_program"], task_axes_for(robot))
        for k, (name, unit, signed) in enumerate(names):
            cols["task"].append(task.name)
            cols["index"].append(k + 1)
            cols["name"].append(name)
            cols["unit"].append(unit)
            cols["signed"].append(signed)
            cols["d"].append(values[0, k])
            cols["s"].append(values[1, k])
            cols["c"].append(values[2, k])
    d, s, c = (np.array(cols[k], float) for k in ("d", "s", "c"))
    cm = np.array([u == "cm" for u in cols["unit"]], bool)
    return pa.table(
        {
            "task": cols["task"],
            "index": np.array(cols["index"], np.int32),
            "name": cols["name"],
            "unit": cols["unit"],
            "signed": np.array(cols["signed"], bool),
            "design_cm": pa.array(np.where(cm, d, np.nan), mask=~cm),
            "signature_cm": pa.array(np.where(cm, s, np.nan), mask=~cm),
            "design_deg": pa.array(np.where(cm, np.nan, d), mask=cm),
            "signature_deg": pa.array(np.where(cm, np.nan, s), mask=cm),
            "compensated_cm": pa.array(c, mask=~cm | np.isnan(c)),
            "compensated_deg": pa.array(c, mask=cm | np.isnan(c)),
            "improvement": improvement(d, s),
        }
    )


STAGE = Stage(
    "evaluate_indices",
    2,  # 2: the compensated controller's columns (issue 30)
    ("evaluate_measurements", "evaluate_program", "session"),
    NoParams(),
    compute,
    "performance indices and improvement factors",
)
