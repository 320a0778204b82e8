"""Targets from files and solutions to files: the I/O of ``pipeline ik --targets``, and
the joint files of ``pipeline fk --q-file``.

:mod:`pipeline.control.controller` holds the solving; this module reads and writes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.control.controller import Controller, solve_poses
from pipeline.errors import ArmsigError
from pipeline.kinematics.ik import IKResult
from pipeline.robots.description import RobotDescription

#: Columns of an ``ik --targets`` file: the poses, in the design base frame.
TARGET_COLUMNS = ("x_cm", "y_cm", "z_cm", "rx_deg", "ry_deg", "rz_deg")


def read_targets(path: str | Path) -> tuple[Any, np.ndarray, list[str | None] | None]:
    """The table of an ``ik --targets`` Arrow IPC file (or CSV with a header when the name
    ends ``.csv``), its poses (m, 6) (cm, deg) and
    its optional ``branch`` column; a one-line error naming the file and the column
    for anything else (a missing file, a column that is missing, repeated, not numeric,
    null, NaN or infinite, a branch that is not text)."""
    import pyarrow as pa

    p = Path(path)
    table = _read_table(p, "--targets", TARGET_COLUMNS, csv=p.suffix.lower() == ".csv")
    poses = numeric_columns(table, TARGET_COLUMNS, f"--targets {p}")
    branches = None
    if "branch" in table.column_names:
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


def joint_columns(robot: RobotDescription) -> tuple[str, ...]:
    """The joint columns of ``ik --targets`` output and ``fk --q-file`` input:
    ``q1_deg``, ..., ``q3_cm`` (one per joint, its boundary unit)."""
    return tuple(f"q{i + 1}_{j.unit}" for i, j in enumerate(robot.joints))


def read_joints(
    path: str | Path, robot: RobotDescription, option: str = "--q-file"
) -> tuple[Any, np.ndarray]:
    """The table of an ``fk --q-file`` file (Arrow IPC, or CSV with a header when the name
    ends ``.csv``) and its joint readings (m, n) (deg / cm) from the columns of
    :func:`joint_columns` (what ``ik --targets`` writes); one-line errors as
    :func:`read_targets`, naming ``option`` (``export --over`` reads the same files)."""
    p = Path(path)
    names = joint_columns(robot)
    table = _read_table(p, option, names, csv=p.suffix.lower() == ".csv")
    if not table.num_rows:
        raise ArmsigError(f"{option} {p}: no rows", expected="one configuration per row")
    return table, numeric_columns(table, names, f"{option} {p}")


def holds_joints(path: str | Path, robot: RobotDescription) -> bool:
    """Whether the targets file ``path`` holds joint readings (:func:`joint_columns`) and
    no poses: a program's joint targets, taught on the nominal model."""
    p = Path(path)
    if not p.is_file():
        return False
    names = _read_table(p, "--targets", (), csv=p.suffix.lower() == ".csv").column_names
    return TARGET_COLUMNS[0] not in names and all(c in names for c in joint_columns(robot))


def _read_table(p: Path, option: str, columns: tuple[str, ...], csv: bool) -> Any:
    """The table of the Arrow IPC (or ``csv``: CSV) file ``p`` given as ``option``, with
    ``columns`` present once each; else a one-line error."""
    import pyarrow as pa

    kind = "a CSV file with a header" if csv else "an Arrow IPC file"
    if not p.is_file():
        raise ArmsigError(
            f"{option} {p}: " + ("is a folder" if p.is_dir() else "no such file"),
            expected=f"{kind} with columns " + ", ".join(columns),
        )
    try:
        if csv:
            import pyarrow.csv as pacsv

            # Only empty cells are null: "nan" is a number, refused as not finite.
            table = pacsv.read_csv(str(p), convert_options=pacsv.ConvertOptions(null_values=[""]))
        else:
            import pyarrow.ipc as ipc

            with pa.OSFile(str(p), "rb") as fh:
                table = ipc.open_file(fh).read_all()
    except (OSError, pa.ArrowException) as exc:
        raise ArmsigError(
            f"{option} {p}: not {kind}", got=str(exc).splitlines()[0], fix="check the file"
        ) from exc
    names = table.column_names
    repeated = sorted({c for c in names if names.count(c) > 1})
    if repeated:
        raise ArmsigError(f"{option} {p}: column {repeated[0]!r} appears more than once")
    missing = [c for c in columns if c not in names]
    if missing:
        raise ArmsigError(
            f"{option} {p}: missing column(s) {', '.join(missing)}",
            expected=", ".join(columns),
            got=", ".join(names) or "no columns",
        )
    return table


def numeric_columns(table: Any, columns: tuple[str, ...], where: str) -> np.ndarray:
    """The ``columns`` of ``table`` as finite numbers (m, k); else a one-line error
    naming ``where`` (the option and file) and the column."""
    import pyarrow as pa

    out = np.empty((table.num_rows, len(columns)))
    for k, name in enumerate(columns):
        col = table.column(name)
        at = f"{where}: column {name!r}"
        if not (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)):
            raise ArmsigError(f"{at} is not numeric", expected="numbers", got=str(col.type))
        if col.null_count:
            row = col.is_null().to_pylist().index(True)
            raise ArmsigError(f"{at} has {col.null_count} null(s), the first in row {row}")
        out[:, k] = col.to_numpy()
        bad = np.flatnonzero(~np.isfinite(out[:, k]))
        if bad.size:
            raise ArmsigError(
                f"{at} has {bad.size} value(s) that are not finite, the first in row {bad[0]}",
                got=str(out[bad[0], k]),
            )
    return out


def check_output(
    out: str | Path,
    targets: str | Path,
    force: bool,
    suggest: str = "joints.arrow",
    option: str = "--targets",
) -> None:
    """Refuse an ``--out`` that is the input file (``option``; the fix suggests ``suggest``),
    or (unless ``force``) an existing file (:func:`pipeline.atomic.check_new_file`): checked
    before any solving."""
    from pipeline.atomic import check_new_file

    if Path(out).resolve() == Path(targets).resolve():
        raise ArmsigError(
            f"--out {out} is the {option} file",
            expected="an output file other than the input",
            fix=f"--out {suggest}",
        )
    check_new_file(out, "--out", force)


def solved_columns(
    controller: Controller,
    poses: np.ndarray,
    branches: list[str | None] | None,
    method: str,
    near: np.ndarray | None = None,
) -> tuple[np.ndarray, IKResult, dict[str, Any]]:
    """Solve ``poses`` (m, 6) (cm, deg; design base frame) with ``controller``: the joint
    readings (m, n) (deg / cm), the raw result, and the output columns of ``ik --targets``
    (joints, ``converged``, ``iterations``, residuals, ``status``, ``branch_changed``,
    ``outside_limits``) as Arrow arrays by name."""
    import pyarrow as pa

    from pipeline.control.limits import outside_names
    from pipeline.kinematics.ik import STATUS_NAMES

    q, res = solve_poses(controller, poses[:, :3], poses[:, 3:], branches, method, near)
    outside = [",".join(names) for names in outside_names(controller.robot, res.q)]
    extra: dict[str, Any] = {}
    for i, name in enumerate(joint_columns(controller.robot)):
        extra[name] = pa.array(q[:, i], pa.float64())
    extra.update(
        converged=pa.array(res.converged, pa.bool_()),
        iterations=pa.array(res.iterations, pa.int32()),
        position_error_cm=pa.array(res.position_error_cm, pa.float64()),
        orientation_error_deg=pa.array(np.degrees(res.orientation_error_rad), pa.float64()),
        status=pa.array([STATUS_NAMES[int(s)] for s in res.status], pa.string()),
        branch_changed=pa.array(res.branch_changed, pa.bool_()),
        outside_limits=pa.array(outside, pa.string()),
    )
    return q, res, extra


def write_csv(path: Path, table: Any) -> None:
    """``table`` as CSV with a header (pyarrow's writer, numbers at full precision), atomically."""
    import pyarrow.csv as pacsv

    from pipeline.atomic import atomic_write

    with atomic_write(path, "wb") as fh:
        pacsv.write_csv(table, fh)


def write_columns(table: Any, extra: dict[str, Any], out: str | Path, meta: dict[str, str]) -> str:
    """Write ``table`` with the columns ``extra`` (by name, replacing the table's columns
    of the same names) to ``out`` (atomically: Arrow IPC, or CSV when its name ends
    ``.csv``); the note on what was replaced ("" if nothing)."""
    from pipeline.stages.tables import write_table

    replaced = [c for c in table.column_names if c in extra]
    table = table.drop_columns(replaced)
    for name, values in extra.items():
        table = table.append_column(name, values)
    if Path(out).suffix.lower() == ".csv":  # plain CSV for the tools that read no Arrow
        write_csv(Path(out), table)
    else:
        write_table(Path(out), table, meta)
    return f" (replaced the input's {', '.join(replaced)})" if replaced else ""


def reached_summary(res: IKResult, out: str | Path) -> tuple[str, int]:
    """The summary line of a solved targets file and the number of targets not reached."""
    from pipeline.kinematics.ik import STATUS_OUT_OF_LIMITS

    failed = int((~res.converged).sum())
    limited = int((res.status == STATUS_OUT_OF_LIMITS).sum())
    where = f" ({limited} out_of_limits: no solution inside the joint limits)" if limited else ""
    m = len(res.converged)
    return f"{m - failed} of {m} targets converged{where}; wrote {out}", failed


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
    a session's measurements never (:func:`check_output`). Returns a summary line and the
    number of targets not reached."""
    table, poses, branches = read_targets(targets)
    check_output(out, targets, force)
    _, res, extra = solved_columns(controller, poses, branches, method, near)
    meta = {"method": method, "signature": controller.robot.name, "tool": tool}
    note = write_columns(table, extra, out, meta)
    summary, failed = reached_summary(res, out)
    return summary + note, failed
