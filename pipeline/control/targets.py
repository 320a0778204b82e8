"""Targets from files and solutions to files: the I/O of ``pipeline ik --targets``.

:mod:`pipeline.control.controller` holds the solving; this module reads and writes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.control.controller import Controller, solve_poses
from pipeline.errors import ArmsigError

#: Columns of an ``ik --targets`` file: the poses, in the design base frame.
TARGET_COLUMNS = ("x_cm", "y_cm", "z_cm", "rx_deg", "ry_deg", "rz_deg")


def read_targets(path: str | Path) -> tuple[Any, np.ndarray, list[str | None] | None]:
    """The table of an ``ik --targets`` Arrow IPC file, its poses (m, 6) (cm, deg) and
    its optional ``branch`` column; a one-line error naming the file and the column
    for anything else (a missing file, a column that is missing, repeated, not numeric,
    null, NaN or infinite, a branch that is not text)."""
    import pyarrow as pa
    import pyarrow.ipc as ipc

    p = Path(path)
    if not p.is_file():
        raise ArmsigError(
            f"--targets {p}: " + ("is a folder" if p.is_dir() else "no such file"),
            expected="an Arrow IPC file with columns " + ", ".join(TARGET_COLUMNS),
        )
    try:
        with pa.OSFile(str(p), "rb") as fh:
            table = ipc.open_file(fh).read_all()
    except (OSError, pa.ArrowException) as exc:
        raise ArmsigError(f"--targets {p}: not an Arrow IPC file", got=str(exc)) from exc
    names = table.column_names
    repeated = sorted({c for c in names if names.count(c) > 1})
    if repeated:
        raise ArmsigError(f"--targets {p}: column {repeated[0]!r} appears more than once")
    missing = [c for c in TARGET_COLUMNS if c not in names]
    if missing:
        raise ArmsigError(
            f"--targets {p}: missing column(s) {', '.join(missing)}",
            expected=", ".join(TARGET_COLUMNS),
        )
    poses = np.empty((table.num_rows, len(TARGET_COLUMNS)))
    for k, name in enumerate(TARGET_COLUMNS):
        col = table.column(name)
        where = f"--targets {p}: column {name!r}"
        if not (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)):
            raise ArmsigError(f"{where} is not numeric", expected="numbers", got=str(col.type))
        if col.null_count:
            row = col.is_null().to_pylist().index(True)
            raise ArmsigError(f"{where} has {col.null_count} null(s), the first in row {row}")
        poses[:, k] = col.to_numpy()
        bad = np.flatnonzero(~np.isfinite(poses[:, k]))
        if bad.size:
            raise ArmsigError(
                f"{where} has {bad.size} value(s) that are not finite, the first in row {bad[0]}",
                got=str(poses[bad[0], k]),
            )
    branches = None
    if "branch" in names:
        col = table.column("branch")
        if not (pa.types.is_string(col.type) or pa.types.is_large_string(col.type)):
            if not pa.types.is_null(col.type):
                raise ArmsigError(
                    f"--targets {p}: column 'branch' is not text",
                    expected="branch names such as right-up-noflip, or null",
                    got=str(col.type),
                )
        branches = col.to_pylist()
    return table, poses, branches


def solve_arrow(
    controller: Controller,
    targets: str | Path,
    out: str | Path,
    method: str,
    tool: str = "signature",
    near: np.ndarray | None = None,
    force: bool = False,
) -> tuple[str, int]:
    """Solve an Arrow file of poses and write the joints beside them (atomically).

    ``tool`` names the tool the poses are for, for the output's metadata (the
    controller's own tool: see :meth:`Controller.with_tool`). Columns of the input
    that carry an output's name (a file that is itself an output) are replaced.
    ``outside_limits``: the joints outside their limits, comma-separated ("" inside;
    a row whose status is ``out_of_limits`` has no in-limit solution on its branch).
    ``out`` is checked before the solve: an existing file is replaced only with ``force``,
    a session's measurements never (:func:`pipeline.atomic.check_new_file`). Returns a
    summary line and the number of targets not reached."""
    import pyarrow as pa

    from pipeline.atomic import check_new_file
    from pipeline.control.limits import outside_names
    from pipeline.kinematics.ik import STATUS_NAMES, STATUS_OUT_OF_LIMITS
    from pipeline.stages.tables import write_table

    table, poses, branches = read_targets(targets)
    if Path(out).resolve() == Path(targets).resolve():
        raise ArmsigError(
            f"--out {out} is the --targets file",
            expected="an output file other than the input",
            fix="--out joints.arrow",
        )
    check_new_file(out, "--out", force)
    q, res = solve_poses(controller, poses[:, :3], poses[:, 3:], branches, method, near)
    outside = [",".join(names) for names in outside_names(controller.robot, res.q)]
    extra: dict[str, pa.Array] = {}
    for i, j in enumerate(controller.robot.joints):
        extra[f"q{i + 1}_{j.unit}"] = pa.array(q[:, i], pa.float64())
    extra.update(
        converged=pa.array(res.converged, pa.bool_()),
        iterations=pa.array(res.iterations, pa.int32()),
        position_error_cm=pa.array(res.position_error_cm, pa.float64()),
        orientation_error_deg=pa.array(np.degrees(res.orientation_error_rad), pa.float64()),
        status=pa.array([STATUS_NAMES[int(s)] for s in res.status], pa.string()),
        branch_changed=pa.array(res.branch_changed, pa.bool_()),
        outside_limits=pa.array(outside, pa.string()),
    )
    replaced = [c for c in table.column_names if c in extra]
    table = table.drop_columns(replaced)
    for name, values in extra.items():
        table = table.append_column(name, values)
    meta = {"method": method, "signature": controller.robot.name, "tool": tool}
    write_table(Path(out), table, meta)
    failed = int((~res.converged).sum())
    limited = int((res.status == STATUS_OUT_OF_LIMITS).sum())
    note = f" (replaced the input's {', '.join(replaced)})" if replaced else ""
    where = f" ({limited} out_of_limits: no solution inside the joint limits)" if limited else ""
    return f"{len(q) - failed} of {len(q)} targets converged{where}; wrote {out}{note}", failed
