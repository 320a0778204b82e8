"""Stage ``evaluate_measurements``: the instrument readings of ``evaluation.mcap``.

Refuses a recording made for another program than ``evaluate_program``'s
(for example after a new signature): the tasks must be run again.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.evaluate_teach import by_key, joints_from_columns

#: Recorded commands may be logged to 6 decimals (deg / cm), as /robot/joint_state is.
COMMAND_TOL = 1e-6
KEY = ("task", "controller", "point")  # of /eval/program and /eval/measurement


#: Controllers a recording may leave out: one made before the compensated run existed (a
#: hardware session's, say) is scored for the design and signature controllers it has.
OPTIONAL_CONTROLLERS = ("compensated",)


def program_matches(
    recorded: list[dict[str, Any]], program: pa.Table, tol: float = 0.0, partial: bool = False
) -> bool:
    """Whether the recorded ``/eval/program`` is the executable part of ``program``
    (the same rows, matched by (task, controller, point) whatever their log times, joints
    within ``tol`` deg / cm). ``partial``: a recording without the runs of
    :data:`OPTIONAL_CONTROLLERS` matches the rest of the program.

    Executable: the tasks whose every row (every controller) is ``ok``.
    """
    want = sorted(recorded_program_rows(program), key=lambda row: row[:3])
    if partial:
        present = {r["controller"] for r in recorded}
        want = [w for w in want if w[1] in present or w[1] not in OPTIONAL_CONTROLLERS]
    if len(want) != len(recorded):
        return False
    recorded = sorted(recorded, key=lambda r: tuple(r[k] for k in KEY))
    for (t, c, p, q), r in zip(want, recorded, strict=True):
        if (t, c, p) != (r["task"], r["controller"], int(r["point"])):
            return False
        got = np.asarray(r["q_commanded"], float)
        if got.shape != (len(q),) or not np.all(np.abs(got - q) <= tol):
            return False
    return True


def recorded_program_rows(program: pa.Table) -> list[tuple[str, str, int, tuple[float, ...]]]:
    """The rows of ``program`` a rig should execute: (task, controller, point, q)."""
    tasks = program.column("task").to_pylist()
    ok = program.column("ok").to_pylist()
    bad = {t for t, o in zip(tasks, ok, strict=True) if not o}
    q = joints_from_columns(program)
    return [
        (t, c, int(p), tuple(float(v) for v in q[k]))
        for k, (t, c, p) in enumerate(
            zip(
                tasks,
                program.column("controller").to_pylist(),
                program.column("point").to_pylist(),
                strict=True,
            )
        )
        if t not in bad
    ]


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    rec = inputs["evaluation"]
    program = by_key(rec.program, KEY, f"{rec.path}: /eval/program")
    if not program_matches(program, inputs["evaluate_program"], COMMAND_TOL, partial=True):
        raise StageError(
            f"{rec.path} was recorded for another joint program than evaluate_program's",
            expected="the /eval/program of the current signature",
            fix="run the new program on the robot and record it again "
            "(`pipeline evaluate` does so for a simulated session)",
        )
    ms = by_key(rec.measurements, KEY, f"{rec.path}: /eval/measurement")

    def col(key: str, k: int | None = None) -> pa.Array:
        vals = [m.get(key) if k is None else (m[key][k] if key in m else None) for m in ms]
        return pa.array(vals, pa.float64())

    def position(k: int) -> pa.Array:
        vals = [(m.get("xy_cm") or m.get("xyz_cm") or [None] * 3)[k] for m in ms]
        return pa.array(vals, pa.float64())

    return pa.table(
        {
            "task": [m["task"] for m in ms],
            "controller": [m["controller"] for m in ms],
            "point": np.array([m["point"] for m in ms], np.int32),
            "instrument": [m["instrument"] for m in ms],
            "length_cm": col("length_cm"),
            "x_cm": position(0),
            "y_cm": position(1),
            "z_cm": col("xyz_cm", 2),
            "rx_deg": col("rotation_deg", 0),
            "ry_deg": col("rotation_deg", 1),
            "rz_deg": col("rotation_deg", 2),
        }
    )


STAGE = Stage(
    "evaluate_measurements",
    3,  # 3: a recording without the compensated run is scored for the others (issue 30)
    ("evaluation", "evaluate_program"),
    NoParams(),
    compute,
    "instrument readings of the executed programs",
)
