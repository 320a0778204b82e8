"""Stage ``evaluate_teach``: the recorded teach readings of every task (Section 6.5)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import NoParams, Stage


def by_key(rows: list[dict[str, Any]], keys: tuple[str, ...], where: str) -> list[dict[str, Any]]:
    """``rows`` (messages of one evaluation channel) sorted by their key fields, never by
    log time; a key recorded twice is refused, naming it and ``where`` (file: topic)."""
    ordered = sorted(rows, key=lambda r: tuple(r[k] for k in keys))
    for a, b in zip(ordered, ordered[1:], strict=False):
        if all(a[k] == b[k] for k in keys):
            raise StageError(
                f"{where} key " + ", ".join(f"{k}={a[k]!r}" for k in keys) + " is recorded twice",
                expected="one message per key",
                fix="record the evaluation again (`pipeline evaluate` does so for a simulated "
                "session)",
            )
    return ordered


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
    rows = by_key(rec.teach, ("task", "point"), f"{rec.path}: /eval/teach")
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
    2,
    ("evaluation",),
    NoParams(),
    compute,
    "teach readings of the task workspace frames",
)
