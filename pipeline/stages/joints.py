"""Stage ``joints``: commanded and encoder joint positions of every configuration.

Readings become joint values here, through the robot's coupling when it has one
(joint = C · reading + offset, schemas/robot_description.md); every later stage
sees joint values only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.stages.base import RECORDING, NoParams, Stage


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.robots.description import description_from_dict

    rec = inputs[RECORDING]
    k, n = rec.q_encoder.shape
    robot = description_from_dict(rec.robot["robot"], source="/robot/description")
    is_p = np.tile(robot.prismatic, k)
    cmd = robot.joints_from_readings(rec.q_commanded).ravel()
    enc = robot.joints_from_readings(rec.q_encoder).ravel()
    payload = rec.joint_payload_kg
    return pa.table(
        {
            "sweep": np.repeat(rec.joint_sweep, n).astype(np.int32),
            "step": np.repeat(rec.joint_step, n).astype(np.int32),
            "joint": np.tile(np.arange(1, n + 1), k).astype(np.int32),
            "q_cmd_deg": pa.array(cmd, mask=is_p),
            "q_deg": pa.array(enc, mask=is_p),
            "q_cmd_cm": pa.array(cmd, mask=~is_p),
            "q_cm": pa.array(enc, mask=~is_p),
            "t_s": np.repeat(rec.joint_t_s, n),
            "payload_kg": pa.array(np.repeat(payload, n), mask=np.repeat(np.isnan(payload), n)),
            **source_columns(rec.joint_source_file, rec.joint_source_line, n),
            **{
                name: pa.array(np.repeat(v, n), mask=np.repeat(np.isnan(v), n))
                for name, v in zip(DRIFT, rec.joint_drift_cm.T, strict=True)
            },
        }
    )


#: The fixed targets' drift per configuration (importers/fixed.py), before and after.
DRIFT = ("tracker_drift_cm", "tracker_residual_cm")


def source_columns(files: np.ndarray, lines: np.ndarray, n: int = 1) -> dict[str, pa.Array]:
    """``source_file`` and ``source_line`` of each configuration, repeated ``n`` times (one
    row per joint): where an imported row came from, null when not recorded."""
    files = np.asarray(files, str)
    # by runs of one file, not a Python string a row (a million rows' six joint rows:
    # 6 million strings and their 0.8 GB (K·n, len) array, issue 45)
    changed = np.r_[True, files[1:] != files[:-1]] if len(files) else np.zeros(0, bool)
    start = np.flatnonzero(changed)
    names, run = np.unique(files[start], return_inverse=True)
    code = np.repeat(np.repeat(run, np.diff(np.r_[start, len(files)])), n).astype(np.int32)
    absent = np.repeat(files == "", n)
    dictionary = pa.DictionaryArray.from_arrays(
        pa.array(code, mask=absent), pa.array(names.tolist(), pa.string())
    )
    ln = np.repeat(lines, n)
    return {
        "source_file": dictionary.cast(pa.string()),
        "source_line": pa.array(ln.astype(np.int32), mask=ln <= 0),
    }


def sources_at(joints: pa.Table | None, sweep: np.ndarray, step: np.ndarray) -> dict[str, pa.Array]:
    """``source_file`` and ``source_line`` of the configurations (sweep, step), joined by
    that key from the ``joints`` table (null where not recorded, or no table; of a key
    recorded twice, the last row). Columns at once, never a row at a time (issue 45)."""
    if joints is None or "source_file" not in joints.column_names:
        return source_columns(np.full(len(sweep), ""), np.zeros(len(sweep), np.int64))
    import pyarrow.compute as pc

    i, found = rows_of_keys(joints, sweep, step)
    files = joints.column("source_file").take(pa.array(i)).combine_chunks()
    keep = pc.and_kleene(pa.array(found), pc.not_equal(files, ""))  # null: a null file
    lines = joints.column("source_line").take(pa.array(i)).to_numpy(zero_copy_only=False)
    lines = np.nan_to_num(np.asarray(lines, float), nan=0.0)
    return {
        "source_file": pc.if_else(keep, files, pa.scalar(None, pa.string())),
        "source_line": pa.array(lines.astype(np.int32), mask=(lines <= 0) | ~found),
    }


def rows_of_keys(
    table: pa.Table, sweep: np.ndarray, step: np.ndarray
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    """For each configuration (sweep, step), the last row of ``table`` (columns ``sweep``
    and ``step``) with that key (0 where none) and whether there is one: a sorted join."""
    have = _key(table.column("sweep").to_numpy(), table.column("step").to_numpy())
    want = _key(np.asarray(sweep), np.asarray(step))
    if len(have) == 0:
        return np.zeros(len(want), np.int64), np.zeros(len(want), bool)
    order = np.argsort(have, kind="stable")  # of a key recorded twice, the last one counts
    i = order[np.maximum(np.searchsorted(have[order], want, side="right") - 1, 0)]
    return i.astype(np.int64), have[i] == want


def _key(sweep: np.ndarray, step: np.ndarray) -> npt.NDArray[np.int64]:
    """One int64 per (sweep, step), in their lexicographic order (steps are int32)."""
    return np.asarray(sweep, np.int64) * (1 << 32) + np.asarray(step, np.int64)


STAGE = Stage(
    "joints",
    5,  # 3: t_s from the measurement times (MCAP publish_time), not the log times (issue 33);
    # 4: payload_kg (issue 27); 5: source_file and source_line of an imported row and the
    # tracker's drift by fixed targets (issue 42)
    (RECORDING,),
    NoParams(),
    compute,
    "joint positions per configuration",
)
