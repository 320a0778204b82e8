"""Statistics and Arrow tables of a Monte-Carlo study (Section 7.2.1: mean, variance, std).

Every robot of every setting has its own random stream, spawned from the study
seed by :class:`numpy.random.SeedSequence`, so results do not depend on how the
robots are split into batches or worker processes.

Standard errors (normal theory, R robots): of the mean ``s / √R``; of the
standard deviation ``s / √(2 (R − 1))``.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from pipeline.kinematics.transforms import Array


def robot_seeds(seed: int, study: str, setting: int, robots: int) -> list[np.random.SeedSequence]:
    """Independent seed sequences of the robots of one setting of one study.

    The stream of robot ``r`` depends only on ``(seed, study, setting, r)``.
    """
    root = np.random.SeedSequence(seed, spawn_key=(zlib.crc32(study.encode()), setting))
    return root.spawn(robots)


def generators(seeds: list[np.random.SeedSequence]) -> list[np.random.Generator]:
    """One PCG64 generator per seed sequence."""
    return [np.random.default_rng(s) for s in seeds]


@dataclass(frozen=True)
class Summary:
    """Per-setting statistics of R robots; arrays of shape (S, K) (settings × indices)."""

    mean: Array
    std: Array
    se_mean: Array
    se_std: Array
    robots: int


def summarize(values: Array) -> Summary:
    """Mean, sample std (ddof = 1) and their standard errors over the robot axis.

    Parameters
    ----------
    values : ndarray, shape (S, R, K)
        Settings × robots × indices, R ≥ 2.
    """
    v = np.asarray(values, float)
    r = v.shape[1]
    if r < 2:
        raise ValueError(f"summarize needs at least 2 robots per setting, got {r}")
    mean = v.mean(axis=1)
    std = v.std(axis=1, ddof=1)
    return Summary(mean, std, std / np.sqrt(r), std / np.sqrt(2.0 * (r - 1)), r)


def arrow_field(name: str, typ: pa.DataType, unit: str, description: str) -> pa.Field:
    """A nullable column of a Monte-Carlo table, its unit and description in its metadata."""
    return pa.field(name, typ, nullable=True, metadata={"unit": unit, "description": description})


def _by_unit(values: Array, units: list[str]) -> dict[str, Array]:
    """Split values (..., K) into ``cm`` and ``deg`` columns, and a unitless ``""`` one when
    an index has no unit (a ratio, a count; the refine study), NaN where the unit differs."""
    u = np.asarray(units)
    kinds = ("cm", "deg", "") if "" in units else ("cm", "deg")
    return {k: np.where(u == k, values, np.nan) for k in kinds}


def _suffixed(name: str, unit: str) -> str:
    """``value_cm``, ``value_deg``, or ``value`` for a unitless index."""
    return f"{name}_{unit}" if unit else name


def _masked(a: Array) -> pa.Array:
    flat = np.ravel(a)
    return pa.array(flat, type=pa.float64(), mask=np.isnan(flat))


def indices_table(
    study: str,
    parameter: str,
    parameter_unit: str,
    settings: Array,
    values: Array,
    names: list[str],
    units: list[str],
) -> pa.Table:
    """Long table: one row per (setting, robot, index).

    Parameters
    ----------
    parameter : str
        Column name of the swept parameter, unit suffix included (e.g. ``sigma_e_deg``).
    settings : ndarray, shape (S,)
    values : ndarray, shape (S, R, K)
    names, units : list of str, length K
    """
    s, r, k = values.shape
    cols = _by_unit(values, units)
    what = {"cm": "a length", "deg": "an angle", "": "without unit"}
    schema = pa.schema(
        [
            arrow_field("study", pa.string(), "", "study name"),
            arrow_field("setting", pa.int32(), "", "setting number, 0-based"),
            arrow_field(parameter, pa.float64(), parameter_unit, "swept parameter"),
            arrow_field("robot", pa.int32(), "", "robot number within the setting, 0-based"),
            arrow_field(
                "index", pa.string(), "", "performance index (Section 7.2.1), unit suffixed"
            ),
            *(
                arrow_field(_suffixed("value", u), pa.float64(), u, f"index value when {what[u]}")
                for u in cols
            ),
        ]
    )
    return pa.table(
        [
            pa.array([study] * (s * r * k)),
            pa.array(np.repeat(np.arange(s), r * k).astype(np.int32)),
            pa.array(np.repeat(np.asarray(settings, float), r * k)),
            pa.array(np.tile(np.repeat(np.arange(r), k), s).astype(np.int32)),
            pa.array(np.tile(np.asarray(names), s * r)),
            *(_masked(c) for c in cols.values()),
        ],
        schema=schema,
    )


def summary_table(
    study: str,
    parameter: str,
    parameter_unit: str,
    settings: Array,
    summary: Summary,
    names: list[str],
    units: list[str],
    signed: list[bool],
) -> pa.Table:
    """One row per (setting, index): mean, std and their standard errors."""
    s, k = summary.mean.shape
    fields = [
        arrow_field("study", pa.string(), "", "study name"),
        arrow_field("setting", pa.int32(), "", "setting number, 0-based"),
        arrow_field(parameter, pa.float64(), parameter_unit, "swept parameter"),
        arrow_field("index", pa.string(), "", "performance index, unit suffixed"),
        arrow_field("signed", pa.bool_(), "", "index takes any real value (19 of 34)"),
        arrow_field("robots", pa.int32(), "", "robots in the setting"),
    ]
    arrays = [
        pa.array([study] * (s * k)),
        pa.array(np.repeat(np.arange(s), k).astype(np.int32)),
        pa.array(np.repeat(np.asarray(settings, float), k)),
        pa.array(np.tile(np.asarray(names), s)),
        pa.array(np.tile(np.asarray(signed, bool), s)),
        pa.array(np.full(s * k, summary.robots, np.int32)),
    ]
    for stat, desc in (
        ("mean", "sample mean over the robots"),
        ("std", "sample standard deviation (ddof = 1)"),
        ("se_mean", "standard error of the mean, std / sqrt(R)"),
        ("se_std", "standard error of the std, std / sqrt(2 (R - 1))"),
    ):
        for unit, col in _by_unit(getattr(summary, stat), units).items():
            fields.append(arrow_field(_suffixed(stat, unit), pa.float64(), unit, desc))
            arrays.append(_masked(col))
    return pa.table(arrays, schema=pa.schema(fields))
