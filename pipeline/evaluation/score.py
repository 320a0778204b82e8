"""Score the measured tasks: every index for both controllers and the improvement factor.

Reads only the measurement and program tables (recorded readings and the
desired points of the plan), never the rig's truth.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from pipeline.evaluation import grid12
from pipeline.evaluation.geometry import distance, rotation_from_vector
from pipeline.evaluation.indices import (
    GRID2D_INDICES,
    GRID3D_INDICES,
    LINES1D_UNIT,
    grid2d_indices,
    grid3d_indices,
    line_length_errors,
)
from pipeline.evaluation.tasks import GRID2D_SHAPE, GRID3D_SHAPE, Task

CONTROLLERS = ("design", "signature")


def _select(table: pa.Table, task: str, controller: str) -> dict[str, np.ndarray]:
    """Columns of one (task, controller) as float arrays, ordered by point."""
    rows = [
        k
        for k, (t, c) in enumerate(
            zip(
                table.column("task").to_pylist(),
                table.column("controller").to_pylist(),
                strict=True,
            )
        )
        if t == task and c == controller
    ]
    sub = table.take(rows)
    order = np.argsort(sub.column("point").to_numpy(), kind="stable")
    return {
        name: np.array(sub.column(name).to_pylist(), dtype=float)[order]
        for name in sub.column_names
        if name.endswith(("_cm", "_deg"))
    }


def _xyz(
    cols: dict[str, np.ndarray], keys: tuple[str, ...] = ("x_cm", "y_cm", "z_cm")
) -> np.ndarray:
    return np.column_stack([cols[k] for k in keys])


def task_indices(
    task: Task, measurements: pa.Table, program: pa.Table
) -> tuple[list[tuple[str, str, bool]], np.ndarray]:
    """Index names (name, unit, signed) and values (2, k) for design and signature."""
    want = _xyz(_select(program, task.name, "design"))
    values = []
    for controller in CONTROLLERS:
        m = _select(measurements, task.name, controller)
        if task.name == "lines1d":
            desired = distance(want[0::2], want[1::2])
            values.append(line_length_errors(m["length_cm"], desired))
            names = [
                (f"line{k + 1}_length_error_cm", LINES1D_UNIT, True) for k in range(len(desired))
            ]
        elif task.name == "grid2d":
            marks = _xyz(m, ("x_cm", "y_cm")).reshape(*GRID2D_SHAPE, 2)
            values.append(grid2d_indices(marks, want[:, :2].reshape(*GRID2D_SHAPE, 2)))
            names = list(GRID2D_INDICES)
        elif task.name == "grid3d":
            shape = (*GRID3D_SHAPE, 3)
            w = _xyz(m, ("rx_deg", "ry_deg", "rz_deg")).reshape(shape)
            values.append(
                grid3d_indices(_xyz(m).reshape(shape), w, want.reshape(shape), np.zeros(shape))
            )
            names = list(GRID3D_INDICES)
        else:
            T_des = task.targets()
            T_act = T_des.copy()
            R_dev = rotation_from_vector(np.deg2rad(_xyz(m, ("rx_deg", "ry_deg", "rz_deg"))))
            T_act[:, :3, :3] = R_dev @ T_des[:, :3, :3]
            T_act[:, :3, 3] = _xyz(m)
            # Workspace coordinates: the 34 indices are invariant to one rigid motion of both.
            values.append(grid12.indices34(T_act, T_des))
            names = list(
                zip(grid12.INDEX_NAMES, grid12.INDEX_UNITS, grid12.INDEX_SIGNED, strict=True)
            )
    return names, np.array(values)
