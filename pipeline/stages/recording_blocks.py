"""The ``/points/block`` messages of a point-sensor recording as rows of joint states and
points (issue 45; :mod:`pipeline.contract.blocks`).

Each block's columns are checked as the schemas of ``/robot/joint_state`` and ``/points``
check one message: finite values within the same bounds (a value out of them is refused
naming the column, the bound and the row's key), keys naming a planned position, units
fitting the robot, a source file index within ``source_files``, ``orientation_sigma_deg``
only beside an orientation, and what :mod:`pipeline.stages.recording_points` checks of a
point's values (a unit quaternion, a covariance's smallest σ). The rows then join the
per-configuration messages' and are sorted, paired and checked with them (duplicates,
step gaps, limits) by :mod:`pipeline.stages.recording`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.contract.blocks import BLOCK_SCHEMA, BLOCK_TOPIC, block_columns
from pipeline.errors import RecordingError
from pipeline.stages.recording_keys import key_text, planned_limit, refuse_unplanned
from pipeline.stages.recording_points import MIN_SIGMA_CM, UNIT_TOL
from pipeline.sweeps import sweep_id

#: Bounds of the schemas of /robot/joint_state and /points (schemas/mcap/).
_Q_MAX, _XYZ_MAX, _SIGMA_MAX, _PAYLOAD_MAX, _DRIFT_MAX = 1e5, 1e5, 1e3, 1e4, 1e5
_QUATERNION_MAX = 1.000001
_LINE_MAX = 100_000_000
_UINT64_MAX, _INT64_MAX = (1 << 64) - 1, (1 << 63) - 1
_FIX = "repair the rig's writer; the schema is the contract (schemas/mcap/points_block.json)"


def block_rows(
    p: Path,
    blocks: list[tuple[int, dict[str, Any]]],
    n_points: dict[int, int | None],
    units: list[str],
    one_file: str,
) -> tuple[dict[str, np.ndarray] | None, dict[str, np.ndarray] | None]:
    """The joint-state rows and the point rows (one per row and target, row-major) of the
    blocks (measurement time in ns, payload), in their order, as columns of
    :class:`pipeline.stages.recording.Recording` plus ``t_ns`` (uint64); None, None
    without blocks."""
    if not blocks:
        return None, None
    joints, points = [], []
    for k, (t_ns, m) in enumerate(blocks):
        cols = block_columns(p, k, m)
        sid = sweep_id(m["sweep"])
        rows = int(m["rows"])
        step = m["first_step"] + np.arange(rows, dtype=np.int64)
        sweep = np.full(rows, sid, np.int64)

        def recorded(_: int, sweep_as_recorded: Any = m["sweep"]) -> Any:
            return sweep_as_recorded

        limit = planned_limit(n_points, sid)
        refuse_unplanned(p, BLOCK_TOPIC, sweep, step, limit, recorded, n_points)
        check = _Checker(p, k, sid, step)
        dt = cols["dt_ns"]
        check.bounded("dt_ns", dt, 0, min(_UINT64_MAX - t_ns, _INT64_MAX))
        t = np.uint64(t_ns) + dt.astype(np.uint64)
        if m["units"] != units:
            raise RecordingError(
                f"{p}: /robot/joint_state {key_text(sid, step[0])} does not fit the robot",
                expected=f"{len(units)} joint values in units {units}",
                got=f"units {m['units']} ({BLOCK_TOPIC} message {k}, {rows:,} rows)",
                fix="record one value per joint of /robot/description, deg or cm by joint type",
            )
        cols.setdefault("q_encoder", cols["q_commanded"])  # absent: the same readings
        for name in ("q_commanded", "q_encoder"):
            check.bounded(name, cols[name], -_Q_MAX, _Q_MAX)
        joints.append(_joint_columns(check, m, cols, sweep, step, t, one_file))
        points.append(_point_columns(check, m, cols, sweep, step, t))
    return merged(joints), _with_uncertainty(p, merged(points))


def merged(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The columns of ``parts`` one after the other (the one part as it is)."""
    if len(parts) == 1:
        return parts[0]
    return {k: np.concatenate([c[k] for c in parts]) for k in parts[0]}


def _joint_columns(
    check: _Checker,
    m: dict[str, Any],
    cols: dict[str, np.ndarray],
    sweep: np.ndarray,
    step: np.ndarray,
    t: np.ndarray,
    one_file: str,
) -> dict[str, np.ndarray]:
    rows = len(step)
    payload = cols.get("payload_kg")
    if payload is not None:
        check.bounded("payload_kg", payload, 0.0, _PAYLOAD_MAX)
    files = m.get("source_files")
    index = cols.get("source_file")
    if (files is None) != (index is None):
        check.refuse("source_file without source_files, or source_files without it")
    if index is not None:
        check.bounded("source_file", index, 0, len(files) - 1)  # type: ignore[arg-type]
        source_file = np.array(files, str)[index]
    else:
        source_file = np.full(rows, one_file, dtype=np.array([one_file], str).dtype)
    line = cols.get("source_line")
    if line is not None:
        check.bounded("source_line", line, 0, _LINE_MAX)
    drift = np.full((rows, 2), np.nan)
    for j, name in enumerate(("tracker_drift_cm", "tracker_residual_cm")):
        if name in cols:
            check.bounded(name, cols[name], 0.0, _DRIFT_MAX, nan=True)
            drift[:, j] = cols[name]
    return {
        "joint_sweep": sweep,
        "joint_step": step,
        "t_ns": t,
        "q_commanded": cols["q_commanded"],
        "q_encoder": cols["q_encoder"],
        "joint_payload_kg": np.full(rows, np.nan) if payload is None else payload,
        "joint_source_file": source_file,
        "joint_source_line": np.zeros(rows, np.int64) if line is None else line,
        "joint_drift_cm": drift,
    }


def _point_columns(
    check: _Checker,
    m: dict[str, Any],
    cols: dict[str, np.ndarray],
    sweep: np.ndarray,
    step: np.ndarray,
    t: np.ndarray,
) -> dict[str, np.ndarray]:
    """One point per row and target (row-major), with its σ or diagonal covariance and the
    first target's orientation."""
    targets = list(m["targets"])
    rows, n_t = len(step), len(targets)
    xyz = cols["points_cm"]
    check.bounded("points_cm", xyz, -_XYZ_MAX, _XYZ_MAX)
    sigma = np.full((rows, n_t, 3), np.nan)
    if "sigma_cm" in cols:
        sigma = cols["sigma_cm"]
        check.bounded("sigma_cm", sigma, 0.0, _SIGMA_MAX, above=True)
    wxyz = np.full((rows, n_t, 4), np.nan)
    sigma_o = np.full((rows, n_t), np.nan)
    if "orientation_wxyz" in cols:
        q = cols["orientation_wxyz"]
        check.bounded("orientation_wxyz", q, -_QUATERNION_MAX, _QUATERNION_MAX)
        norm = np.linalg.norm(q, axis=1)
        off = np.flatnonzero(np.abs(norm - 1.0) > UNIT_TOL)
        if len(off):
            r = off[0]
            raise RecordingError(
                f"{check.p}: /points {key_text(sweep[r], step[r], target=targets[0])} "
                "orientation_wxyz is not a unit quaternion",
                expected=f"length 1 (± {UNIT_TOL:g})",
                got=f"length {norm[r]:.9g}",
                fix="normalise the quaternion (w, x, y, z) before recording it",
            )
        wxyz[:, 0] = q
        if "orientation_sigma_deg" in m:
            sigma_o[:, 0] = m["orientation_sigma_deg"]
    elif "orientation_sigma_deg" in m:
        check.refuse("orientation_sigma_deg without the orientation_wxyz column")
    return {
        "point_sweep": np.repeat(sweep, n_t),
        "point_step": np.repeat(step, n_t),
        "point_target": np.tile(np.array(targets, str), rows),
        "t_ns": np.repeat(t, n_t),
        "points_cm": xyz.reshape(-1, 3),
        "sigma_xyz_cm": sigma.reshape(-1, 3),
        "point_wxyz": wxyz.reshape(-1, 4),
        "point_orientation_sigma_deg": sigma_o.reshape(-1),
    }


def _with_uncertainty(p: Path, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The points' ``sigma_xyz_cm`` (P, 3; NaN: none) as a point message's: equal σ its
    ``sigma_cm``, unequal its diagonal ``cov_cm2`` of the σ squared, whose smallest σ is
    refused under :data:`MIN_SIGMA_CM` as there (an equal σ: by the points' reader)."""
    s = cols.pop("sigma_xyz_cm")
    equal = (s[:, 0] == s[:, 1]) & (s[:, 1] == s[:, 2])
    diagonal = np.flatnonzero(~equal & ~np.isnan(s).all(axis=1))
    cols["point_sigma_cm"] = np.where(equal, s[:, 0], np.nan)
    cov = np.full((len(s), 3, 3), np.nan)
    if len(diagonal):
        var = s[diagonal] ** 2
        cov[diagonal] = 0.0
        cov[diagonal[:, None], [0, 1, 2], [0, 1, 2]] = var
        smallest = np.sqrt(var.min(axis=1))
        low = np.flatnonzero(~(smallest >= MIN_SIGMA_CM))
        if len(low):
            k = diagonal[low[0]]
            key = key_text(cols["point_sweep"][k], cols["point_step"][k],
                           target=cols["point_target"][k])  # fmt: skip
            raise RecordingError(
                f"{p}: /points {key} cov_cm2's smallest σ is {smallest[low[0]]:g} cm, under "
                f"{MIN_SIGMA_CM:g} cm (1 nm)",
                expected=f"a standard deviation of at least {MIN_SIGMA_CM:g} cm",
                fix="record the instrument's σ in cm (a σ in m or mm recorded as cm?)",
            )
    cols["point_cov_cm2"] = cov
    return cols


class _Checker:
    """Refusals of block message ``k``'s values, naming the column and the row's key."""

    def __init__(self, p: Path, k: int, sweep: int, step: np.ndarray) -> None:
        self.p, self.k, self.sweep, self.step = p, k, sweep, step

    def refuse(self, got: str) -> None:
        raise RecordingError(
            f"{self.p}: {BLOCK_TOPIC} message {self.k} does not match "
            f"schemas/mcap/{BLOCK_SCHEMA}.json",
            got=got,
            fix=_FIX,
        )

    def bounded(
        self,
        name: str,
        values: np.ndarray,
        lo: float,
        hi: float,
        nan: bool = False,
        above: bool = False,
    ) -> None:
        """Every value of column ``name`` in ``[lo, hi]`` (``above``: ``(lo, hi]``; NaN
        allowed when ``nan``); values are float or int."""
        v = values.reshape(len(values), -1)
        ok = ((v > lo) if above else (v >= lo)) & (v <= hi)
        if nan:
            ok |= np.isnan(v)
        bad = np.argwhere(~ok)
        if len(bad):
            r, _ = bad[0]
            value = v[tuple(bad[0])]
            side = "smaller than or equal to" if value > hi else (
                "bigger than" if above else "bigger than or equal to")  # fmt: skip
            bound = hi if value > hi else lo
            self.refuse(
                f"{name} must be {side} {bound:g}, a finite number: {value:g} at "
                f"{key_text(self.sweep, self.step[r])}",
            )
