"""Stage ``compensate``: speed-of-sound compensation of every cycle (Appendix E)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import Stage, check_param


@dataclass(frozen=True)
class Params:
    """``tol_cm``: the fixed point stops when the position moves less than this
    (1e-9 cm: far below the 0.01 cm resolution, reached in 4-5 iterations)."""

    tol_cm: float = 1e-9
    max_iter: int = 50

    def __post_init__(self) -> None:
        # Above 0.01 cm (the digitizer's resolution) the fixed point would stop at
        # positions off by more than what the rig can measure.
        tol = self.tol_cm
        check_param(self, "compensate", "tol_cm", 0 < tol <= 0.01, "> 0 and <= 0.01 (cm)")
        # 4-5 iterations converge; 10,000 only bounds the run time of a bad setting.
        it = self.max_iter
        check_param(self, "compensate", "max_iter", 1 <= it <= 10_000, ">= 1 and <= 10000")


def cycles_from_ranges(ranges: pa.Table) -> tuple[np.ndarray, np.ndarray]:
    """Raw ranges (M, 5, 4) and the (sweep, step, repeat, t) keys (M, 4) of the ``ranges`` table."""
    n = ranges.num_rows
    if n % 20:
        raise StageError(
            "ranges table is not whole cycles", expected="20 rows per cycle", got=f"{n} rows"
        )
    raw = ranges.column("range_cm").to_numpy(zero_copy_only=False).astype(float).reshape(-1, 5, 4)
    keys = np.stack(
        [
            ranges.column(c).to_numpy()[::20].astype(float)
            for c in ("sweep", "step", "repeat", "t_s")
        ],
        axis=1,
    )
    return raw, keys


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.sensor.compensation import compensate
    from pipeline.sensor.geometry import DigitizerGeometry

    raw, keys = cycles_from_ranges(inputs["ranges"])
    rig = json.loads(inputs["session"].column("rig_json")[0].as_py())
    geometry = DigitizerGeometry.from_dict(rig)
    res = compensate(raw, geometry, tol_cm=params.tol_cm, max_iter=params.max_iter)
    needed = np.concatenate([raw[:, 0:2, 1], raw[:, 2:4, 3], raw[:, 4, 0:3]], axis=1)
    missing = np.isnan(needed).any(axis=1)
    status = np.where(
        missing,
        "missing_echo",
        np.where(~res.valid, "no_solution", np.where(res.converged, "ok", "not_converged")),
    )
    ok = res.valid

    def col(v: np.ndarray) -> pa.Array:
        return pa.array(np.where(ok, v, np.nan), mask=~ok)

    return pa.table(
        {
            "sweep": keys[:, 0].astype(np.int32),
            "step": keys[:, 1].astype(np.int32),
            "repeat": keys[:, 2].astype(np.int32),
            "t_s": keys[:, 3],
            "status": status,
            "f_b": pa.array(res.f_b, mask=np.isnan(res.f_b)),
            "f_d": pa.array(res.f_d, mask=np.isnan(res.f_d)),
            "s_a_cm": col(res.s_abc_cm[:, 0]),
            "s_b_cm": col(res.s_abc_cm[:, 1]),
            "s_c_cm": col(res.s_abc_cm[:, 2]),
            "x_cm": col(res.p_cm[:, 0]),
            "y_cm": col(res.p_cm[:, 1]),
            "z_cm": col(res.p_cm[:, 2]),
            "iterations": res.iterations.astype(np.int32),
        }
    )


STAGE = Stage(
    "compensate",
    1,
    ("ranges", "session"),
    Params(),
    compute,
    "speed-of-sound compensation (App. E)",
)
