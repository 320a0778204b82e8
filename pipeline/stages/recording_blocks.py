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
from pipeline.schemas import mcap_json_schema
from pipeline.stages.recording_keys import key_text, planned_limit, refuse_unplanned
from pipeline.stages.recording_points import (
    MAX_COORD_CM,
    MAX_SIGMA_CM,
    MIN_SIGMA_CM,
    UNIT_TOL,
    checked_quaternion,
    checked_sigma,
)
from pipeline.sweeps import sweep_id

#: Bounds of the schemas of /robot/joint_state and /points (schemas/mcap/), read there.
_STATE = mcap_json_schema("joint_state")["properties"]
_Q_MAX = float(_STATE["q_commanded"]["items"]["maximum"])
_PAYLOAD_MAX = float(_STATE["payload_kg"]["maximum"])
_DRIFT_MAX = float(_STATE["tracker_drift_cm"]["maximum"])
_LINE_MAX = int(_STATE["source_line"]["maximum"])
_QUATERNION_MAX = float(
    mcap_json_schema("points")["properties"]["orientation_wxyz"]["items"]["maximum"]
)
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
    joints: list[dict[str, Any]] = []
    points: list[dict[str, Any]] = []
    for k, (t_ns, m) in enumerate(blocks):
        check = _Checker(p, k, m, block_columns(p, k, m))
        sid, step, cols = check.sweep_id, check.step, check.cols

        def recorded(_: int, sweep_as_recorded: Any = m["sweep"]) -> Any:
            return sweep_as_recorded

        limit = planned_limit(n_points, sid)
        refuse_unplanned(p, BLOCK_TOPIC, check.sweep, step, limit, recorded, n_points)
        dt = cols["dt_ns"]
        check.bounded("dt_ns", dt, 0, min(_UINT64_MAX - t_ns, _INT64_MAX))
        check.t = np.uint64(t_ns) + dt.astype(np.uint64)
        if m["units"] != units:
            raise RecordingError(
                f"{p}: /robot/joint_state {key_text(sid, step[0])} does not fit the robot",
                expected=f"{len(units)} joint values in units {units}",
                got=f"units {m['units']} ({BLOCK_TOPIC} message {k}, {len(step):,} rows)",
                fix="record one value per joint of /robot/description, deg or cm by joint type",
            )
        for name in ("q_commanded", "q_encoder"):
            if name in cols:
                check.bounded(name, cols[name], -_Q_MAX, _Q_MAX)
        joints.append(_joint_columns(check))
        points.append(_point_columns(check))
    joint = merged(joints, {**_ABSENT, "joint_source_file": (one_file, ())})
    if joint["q_encoder"] is None or any(c["q_encoder"] is None for c in joints):
        joint["q_encoder"] = joint["q_commanded"].copy()  # absent: the same readings
        for a, c in zip(np.cumsum([0, *(len(c["t_ns"]) for c in joints)]), joints, strict=False):
            if c["q_encoder"] is not None:
                joint["q_encoder"][a : a + len(c["t_ns"])] = c["q_encoder"]
    return joint, _with_uncertainty(p, merged(points, _ABSENT))


#: A column a block may leave out: its value there and its shape after the rows.
_ABSENT: dict[str, tuple[Any, tuple[int, ...]]] = {
    "joint_payload_kg": (np.nan, ()),
    "joint_source_line": (0, ()),
    "joint_drift_cm": (np.nan, (2,)),
    "sigma_xyz_cm": (np.nan, (3,)),
    "point_wxyz": (np.nan, (4,)),
    "point_orientation_sigma_deg": (np.nan, ()),
}


def merged(
    parts: list[dict[str, Any]], absent: dict[str, tuple[Any, tuple[int, ...]]] | None = None
) -> dict[str, Any]:
    """The columns of ``parts`` one after the other (the one part's as they are); a column
    a part leaves out (None) holds its value of ``absent`` there (None where no part has
    it and ``absent`` does not name it)."""
    absent = absent or {}
    rows = [len(c["t_ns"]) for c in parts]
    out = {}
    for k in parts[0]:
        have = [c[k] for c in parts if c[k] is not None]
        if len(have) == len(parts) == 1:
            out[k] = have[0]
        elif len(have) == len(parts):
            out[k] = np.concatenate(have)
        elif k in absent and not have:  # one read-only value, no memory (issue 45)
            value, shape = absent[k]
            out[k] = np.broadcast_to(np.asarray(value), (sum(rows), *shape))
        elif k in absent:
            value, shape = absent[k]
            dtype = have[0].dtype if have else np.asarray(value).dtype
            if have and dtype.kind == "U":
                dtype = np.result_type(dtype, np.asarray(value).dtype)
            out[k] = np.full((sum(rows), *shape), value, dtype)
            for a, n, c in zip(np.cumsum([0, *rows]), rows, parts, strict=False):
                if c[k] is not None:
                    out[k][a : a + n] = c[k]
        else:
            out[k] = None
    return out


def _joint_columns(check: _Checker) -> dict[str, np.ndarray | None]:
    """A block's joint-state columns, None where it leaves one out (:data:`_ABSENT`)."""
    m, cols, sweep, step, t = check.m, check.cols, check.sweep, check.step, check.t
    payload = cols.get("payload_kg")
    if payload is not None:
        check.bounded("payload_kg", payload, 0.0, _PAYLOAD_MAX)
    files = m.get("source_files")
    index = cols.get("source_file")
    if (files is None) != (index is None):
        check.refuse("source_file without source_files, or source_files without it")
    source_file = None  # absent: the recording's one file (armsig.source)
    if index is not None:
        check.bounded("source_file", index, 0, len(files) - 1)  # type: ignore[arg-type]
        source_file = np.array(files, str)[index]
    line = cols.get("source_line")
    if line is not None:
        check.bounded("source_line", line, 0, _LINE_MAX)
    drift = None
    for j, name in enumerate(("tracker_drift_cm", "tracker_residual_cm")):
        if name in cols:
            check.bounded(name, cols[name], 0.0, _DRIFT_MAX, nan=True)
            drift = np.full((len(step), 2), np.nan) if drift is None else drift
            drift[:, j] = cols[name]
    return {
        "joint_sweep": sweep,
        "joint_step": step,
        "t_ns": t,
        "q_commanded": cols["q_commanded"],
        "q_encoder": cols.get("q_encoder"),
        "joint_payload_kg": payload,
        "joint_source_file": source_file,
        "joint_source_line": line,
        "joint_drift_cm": drift,
    }


def _point_columns(check: _Checker) -> dict[str, np.ndarray | None]:
    """One point per row and target (row-major), with its σ of x, y, z and the first
    target's orientation, None where the block leaves one out (:data:`_ABSENT`)."""
    m, cols, sweep, step, t = check.m, check.cols, check.sweep, check.step, check.t
    targets = list(m["targets"])
    rows, n_t = len(step), len(targets)
    xyz = cols["points_cm"]
    check.bounded("points_cm", xyz, -MAX_COORD_CM, MAX_COORD_CM)
    sigma = cols.get("sigma_cm")
    if sigma is not None:
        check.bounded("sigma_cm", sigma, 0.0, MAX_SIGMA_CM, above=True)
    wxyz = sigma_o = None
    if "orientation_wxyz" in cols:
        q = cols["orientation_wxyz"]
        check.bounded("orientation_wxyz", q, -_QUATERNION_MAX, _QUATERNION_MAX)
        norm = np.linalg.norm(q, axis=1)
        off = np.flatnonzero(np.abs(norm - 1.0) > UNIT_TOL)
        if len(off):  # refused as a point message's
            r = off[0]
            checked_quaternion(check.p, key_text(sweep[r], step[r], target=targets[0]), q[r])
        wxyz = np.full((rows, n_t, 4), np.nan)
        wxyz[:, 0] = q
        sigma_o = np.full((rows, n_t), np.nan)
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
        "sigma_xyz_cm": None if sigma is None else sigma.reshape(-1, 3),
        "point_wxyz": None if wxyz is None else wxyz.reshape(-1, 4),
        "point_orientation_sigma_deg": None if sigma_o is None else sigma_o.reshape(-1),
    }


def _with_uncertainty(p: Path, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The points' ``sigma_xyz_cm`` (P, 3; NaN: none) as a point message's: equal σ its
    ``sigma_cm``, unequal its diagonal ``cov_cm2`` of the σ squared, whose smallest σ is
    refused under :data:`MIN_SIGMA_CM` as there (an equal σ: by the points' reader)."""
    s = cols.pop("sigma_xyz_cm")
    equal = (s[:, 0] == s[:, 1]) & (s[:, 1] == s[:, 2])
    diagonal = np.flatnonzero(~equal & ~np.isnan(s).all(axis=1))
    cols["point_sigma_cm"] = np.where(equal, s[:, 0], np.nan)
    cov = np.broadcast_to(np.nan, (len(s), 3, 3))  # read-only NaN, no memory, unless
    if len(diagonal):  # a point's σ differ by axis
        cov = np.full((len(s), 3, 3), np.nan)
        var = s[diagonal] ** 2
        cov[diagonal] = 0.0
        cov[diagonal[:, None], [0, 1, 2], [0, 1, 2]] = var
        smallest = np.sqrt(var.min(axis=1))
        low = np.flatnonzero(~(smallest >= MIN_SIGMA_CM))
        if len(low):  # refused as a point message's
            k = diagonal[low[0]]
            key = key_text(cols["point_sweep"][k], cols["point_step"][k],
                           target=cols["point_target"][k])  # fmt: skip
            checked_sigma(p, key, float(smallest[low[0]]), "cov_cm2's smallest σ")
    cols["point_cov_cm2"] = cov
    return cols


class _Checker:
    """Block message ``k`` (its payload ``m``, decoded ``cols``, rows' ``sweep``, ``step``
    and times ``t``), and the refusals of its values, naming the column and the row's key."""

    def __init__(self, p: Path, k: int, m: dict[str, Any], cols: dict[str, np.ndarray]) -> None:
        self.p, self.k, self.m, self.cols = p, k, m, cols
        self.sweep_id = sweep_id(m["sweep"])
        self.step = m["first_step"] + np.arange(m["rows"], dtype=np.int64)
        self.sweep = np.full(len(self.step), self.sweep_id, np.int64)
        self.t = np.zeros(0, np.uint64)  # the rows' times (ns), once checked

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
                f"{key_text(self.sweep_id, self.step[r])}",
            )
