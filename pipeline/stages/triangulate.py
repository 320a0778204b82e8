"""Stage ``triangulate``: one target position per configuration from its N_avg cycles.

Outlier rule: for the usable cycles of a configuration, take the median
position and every cycle's distance d_k from it; a cycle is rejected when
``d_k > k · max(1.4826 · median(d), floor_cm)``. With Gaussian noise 1.4826·MAD
estimates σ, so k = 5 rejects essentially no good cycle; the floor (0.005 cm,
half the digitizer's resolution) keeps quantized ranges, whose MAD can be 0,
from rejecting honest cycles. The spurious echoes of the rig's fault model
(5-50 cm) are far beyond that.

With only two usable cycles the median cannot tell which one is wrong: when
they disagree by more than ``pair_max_cm`` (1 cm, some 50 σ of a good pair,
far less than a spurious echo moves a target) both are rejected and the
configuration is left out rather than averaged into a wrong point.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from math import inf
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.stages.base import Stage, check_param
from pipeline.stages.positions import positions


@dataclass(frozen=True)
class Params:
    reject_k: float = 5.0
    floor_cm: float = 0.005
    pair_max_cm: float = 1.0

    def __post_init__(self) -> None:
        # k >= 1 keeps every cycle within 1.4826 median(d) of the median: at least half.
        k, floor, pair = self.reject_k, self.floor_cm, self.pair_max_cm
        check_param(self, "triangulate", "reject_k", 1 <= k < inf, ">= 1 and finite")
        check_param(self, "triangulate", "floor_cm", 0 <= floor < inf, ">= 0 and finite (cm)")
        check_param(self, "triangulate", "pair_max_cm", 0 < pair < inf, "> 0 and finite (cm)")


def robust_mean(p: np.ndarray, k: float, floor_cm: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean of the rows of ``p`` (..., m, 3) that pass the outlier rule, and the kept mask (..., m).

    A leading batch shape (Monte-Carlo robots and configurations) applies the
    rule to every set of m cycles on its own.
    """
    med = np.median(p, axis=-2, keepdims=True)
    d = np.linalg.norm(p - med, axis=-1)
    scale = np.maximum(1.4826 * np.median(d, axis=-1, keepdims=True), floor_cm)
    keep = d <= k * scale
    if p.ndim == 2:  # one set: the mean of the kept rows as such
        return p[keep].mean(axis=0), keep
    mean = np.sum(np.where(keep[..., None], p, 0.0), axis=-2) / keep.sum(-1)[..., None]
    return mean, keep


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    t = inputs["compensate"]
    sweep = t.column("sweep").to_numpy()
    step = t.column("step").to_numpy()
    ok = np.asarray(t.column("status").to_pylist()) == "ok"
    xyz = positions(t)
    keys = sweep.astype(np.int64) * 1_000_000 + step
    uniq, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    rows: dict[str, list[Any]] = {
        c: []
        for c in (
            "sweep",
            "step",
            "x_cm",
            "y_cm",
            "z_cm",
            "n_cycles",
            "n_dropped",
            "n_rejected",
            "n_used",
            "scatter_cm",
        )
    }
    order = np.argsort(first)  # the order of the compensate table: by (sweep, step)
    # Each configuration's cycles, ascending, by one stable sort (not a scan per group).
    by_group = np.argsort(inverse, kind="stable")
    ends = np.cumsum(np.bincount(inverse, minlength=len(uniq)))
    starts = ends - np.bincount(inverse, minlength=len(uniq))
    for g in order:
        members = by_group[starts[g] : ends[g]]
        good = members[ok[members]]
        rows["sweep"].append(int(sweep[first[g]]))
        rows["step"].append(int(step[first[g]]))
        rows["n_cycles"].append(len(members))
        rows["n_dropped"].append(len(members) - len(good))
        if len(good) == 0:
            for c in ("x_cm", "y_cm", "z_cm", "scatter_cm"):
                rows[c].append(None)
            rows["n_rejected"].append(0)
            rows["n_used"].append(0)
            continue
        if len(good) == 2 and np.linalg.norm(xyz[good[0]] - xyz[good[1]]) > params.pair_max_cm:
            for c in ("x_cm", "y_cm", "z_cm", "scatter_cm"):
                rows[c].append(None)
            rows["n_rejected"].append(2)
            rows["n_used"].append(0)
            continue
        mean, keep = robust_mean(xyz[good], params.reject_k, params.floor_cm)
        kept = xyz[good][keep]
        rows["x_cm"].append(float(mean[0]))
        rows["y_cm"].append(float(mean[1]))
        rows["z_cm"].append(float(mean[2]))
        rows["n_rejected"].append(int((~keep).sum()))
        rows["n_used"].append(int(keep.sum()))
        rows["scatter_cm"].append(float(np.sqrt(np.mean(np.sum((kept - mean) ** 2, axis=1)))))
    del uniq
    return pa.table(rows)


STAGE = Stage(
    "triangulate",
    2,
    ("compensate",),
    Params(),
    compute,
    "average of N_avg cycles per configuration",
)
