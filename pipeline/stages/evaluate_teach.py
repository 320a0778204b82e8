"""Stage ``evaluate_teach``: the recorded teach readings of every task (Section 6.5)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import NoParams, Stage


def joint_columns(q: np.ndarray, units: list[str]) -> dict[str, list[list[float]]]:
    """``q_deg`` / ``q_cm`` list columns of joint vectors (m, n), NaN in the other unit's."""
    q = np.asarray(q, float)
    deg = np.array([u == "deg" for u in units])
    return {
        "q_deg": np.where(deg, q, np.nan).tolist(),
        "q_cm": np.where(deg, np.nan, q).tolist(),
    }


def joints_from_columns(table: pa.Table) -> np.ndarray:
    """Joint vectors (m, n) in boundary units from ``q_deg`` / ``q_cm`` list columns."""
    deg = np.array(table.column("q_deg").to_pylist(), float)
    cm = np.array(table.column("q_cm").to_pylist(), float)
    return np.where(np.isnan(deg), cm, deg)


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    rec = inputs["evaluation"]
    rows = rec.teach
    units = rows[0]["units"]
    if any(len(r["q_encoder"]) != len(units) for r in rows):
        raise StageError(
            f"{rec.path}: /eval/teach joint vectors of different lengths",
            expected=f"{len(units)} joints",
        )
    return pa.table(
        {
            "task": [r["task"] for r in rows],
            "point": np.array([r["point"] for r in rows], np.int32),
            **joint_columns(np.array([r["q_encoder"] for r in rows]), units),
        }
    )


STAGE = Stage(
    "evaluate_teach",
    1,
    ("evaluation",),
    NoParams(),
    compute,
    "teach readings of the task workspace frames",
)
