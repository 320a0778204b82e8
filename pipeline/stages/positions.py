"""The sensor-neutral ``positions`` table (``schemas/arrow/positions.json``) and its
sonic stage.

Every stage after the sensor reads target positions from this table only: one row
per (sweep, step, target), sorted by that key. A sonic session fills it from
``triangulate`` (this module's stage; target id :data:`SONIC_TARGET`); a point-sensor
session from ``/points`` (:mod:`pipeline.stages.points`, a stage of the same name).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.schemas import arrow_schema
from pipeline.stages.base import NoParams, Stage

SONIC_TARGET = "sparker"  # the target id of a sonic session's single target
COV_ENTRIES = ("xx", "xy", "xz", "yy", "yz", "zz")
_COV_INDEX = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def positions(table: pa.Table) -> np.ndarray:
    """The ``x_cm, y_cm, z_cm`` columns of a table as an (m, 3) array; null -> NaN."""
    return np.stack(
        [table.column(c).to_numpy(zero_copy_only=False) for c in ("x_cm", "y_cm", "z_cm")], axis=1
    ).astype(float)


def sweep_rows(table: pa.Table, sweep: int, target: str | None = None) -> pa.Table:
    """The rows of one sweep (and one target when given), in table order."""
    import pyarrow.compute as pc  # lazy: ~70 ms of import, which a warm run never needs

    mask = pc.equal(table.column("sweep"), sweep)
    if target is not None:
        mask = pc.and_(mask, pc.equal(table.column("target"), target))
    return table.filter(mask)


def sweep_targets(table: pa.Table, sweep: int) -> list[str]:
    """The target ids measured in one sweep, sorted."""
    return sorted(set(sweep_rows(table, sweep).column("target").to_pylist()))


def recorded_sigma_cm(rows: pa.Table) -> float | None:
    """Median recorded point σ of ``rows`` (``sigma_cm``, or √(trace(cov) / 3)); None when
    no row records one (sonic)."""
    sig = rows.column("sigma_cm").to_numpy(zero_copy_only=False).astype(float)
    trace = sum(
        rows.column(f"cov_{a}_cm2").to_numpy(zero_copy_only=False).astype(float)
        for a in ("xx", "yy", "zz")
    )
    s = np.where(np.isnan(sig), np.sqrt(np.asarray(trace) / 3.0), sig)
    s = s[np.isfinite(s)]
    return float(np.median(s)) if len(s) else None


def positions_table(
    sweep: np.ndarray,
    step: np.ndarray,
    target: np.ndarray,
    xyz: list[float | None] | np.ndarray,
    counts: Mapping[str, np.ndarray],
    scatter_cm: list[float | None],
    sigma_cm: np.ndarray | None = None,
    cov_cm2: np.ndarray | None = None,
    wxyz: np.ndarray | None = None,
    orientation_sigma_deg: np.ndarray | None = None,
    source: Mapping[str, pa.Array] | None = None,
) -> pa.Table:
    """The ``positions`` table, sorted by (sweep, step, target).

    ``xyz`` (m, 3) with NaN or rows of None for no position; ``counts``: ``n_samples``,
    ``n_dropped``, ``n_rejected``, ``n_used`` (m,); ``sigma_cm`` (m,), ``cov_cm2``
    (m, 3, 3), ``wxyz`` (m, 4), ``orientation_sigma_deg`` (m,) with NaN where not recorded
    (None: none recorded); ``source``: ``source_file`` and ``source_line`` (m,) of an
    imported row (None: null, a simulated session).
    """
    m = len(sweep)

    def col(v: np.ndarray | None) -> pa.Array:
        v = np.full(m, np.nan) if v is None else np.asarray(v, float)
        return pa.array(v, pa.float64(), mask=np.isnan(v))

    cols: dict[str, Any] = {
        "sweep": pa.array(sweep, pa.int32()),
        "step": pa.array(step, pa.int32()),
        "target": pa.array([str(t) for t in target], pa.string()),
    }
    p = np.array([[np.nan] * 3 if r is None else r for r in xyz], float).reshape(-1, 3)
    for k, c in enumerate("xyz"):
        cols[f"{c}_cm"] = col(p[:, k])
    cols["sigma_cm"] = col(sigma_cm)
    for name, (i, j) in zip(COV_ENTRIES, _COV_INDEX, strict=True):
        cols[f"cov_{name}_cm2"] = col(None if cov_cm2 is None else cov_cm2[:, i, j])
    for k, c in enumerate("wxyz"):
        cols[f"orientation_{c}"] = col(None if wxyz is None else wxyz[:, k])
    cols["orientation_sigma_deg"] = col(orientation_sigma_deg)
    for name in ("n_samples", "n_dropped", "n_rejected", "n_used"):
        cols[name] = pa.array(counts[name], pa.int32())
    cols["scatter_cm"] = pa.array(scatter_cm, pa.float64())
    cols["source_file"] = pa.nulls(m, pa.string()) if source is None else source["source_file"]
    cols["source_line"] = pa.nulls(m, pa.int32()) if source is None else source["source_line"]
    table = pa.table({n: cols[n] for n in arrow_schema("positions").names})
    order = np.lexsort((np.asarray(target, str), np.asarray(step), np.asarray(sweep)))
    return table.take(pa.array(order))


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    t = inputs["triangulate"]
    m = t.num_rows
    return positions_table(
        t.column("sweep").to_numpy(),
        t.column("step").to_numpy(),
        np.full(m, SONIC_TARGET),
        positions(t),
        {
            "n_samples": t.column("n_cycles").to_numpy(),
            **{c: t.column(c).to_numpy() for c in ("n_dropped", "n_rejected", "n_used")},
        },
        t.column("scatter_cm").to_pylist(),
    )


STAGE = Stage(
    "positions",
    2,  # 2: source_file and source_line, null here (issue 42)
    ("triangulate",),
    NoParams(),
    compute,
    "target positions, sensor-neutral (from triangulate)",
)
