"""Score the measured tasks: every index for each controller and the improvement factor.

Reads only the measurement and program tables (recorded readings and the
desired points of the plan), never the rig's truth.

Arms with fewer than six joints control only some rotation components (task
axes, :func:`pipeline.control.task_axes_for`; a SCARA: the rotation about Z).
Their orientation indices use the controlled components of the measured
rotation vectors only (:func:`restrict_orientation`): the others are set by
the arm's geometry and the fixture's tilt, alike for both controllers.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from pipeline.evaluation import grid12
from pipeline.evaluation.controllers import CONTROLLERS
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

AXIS_LETTERS = "xyz"


def controlled_rotations(task_axes: tuple[int, ...]) -> tuple[int, ...]:
    """Rotation components (0, 1, 2 = about X, Y, Z) among task axes into δ (indices 3-5)."""
    return tuple(a - 3 for a in task_axes if a >= 3)


def dropped_indices(task: str, task_axes: tuple[int, ...]) -> list[str]:
    """Names of the orientation indices of ``task`` an arm with these task axes has no
    controlled component for (left out of the index table)."""
    rot = controlled_rotations(task_axes)
    if len(rot) == 3:
        return []
    if task == "grid3d":
        return [f"relative_orientation_{AXIS_LETTERS[c]}_vertex4_deg" for c in range(3)
                if c not in rot]  # fmt: skip
    if task == "grid12" and not rot:
        return [n for n in grid12.INDEX_NAMES if n.endswith("orientation_error_deg")]
    return []


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
    sub = table.take(pa.array(rows, pa.int64()))  # typed: no rows is an empty take
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
    task: Task,
    measurements: pa.Table,
    program: pa.Table,
    task_axes: tuple[int, ...] = (0, 1, 2, 3, 4, 5),
) -> tuple[list[tuple[str, str, bool]], np.ndarray]:
    """Index names (name, unit, signed) and values (c, k) for the :data:`CONTROLLERS`; a
    controller the recording did not measure (an evaluation recorded before the compensated
    controller existed) has NaN values.

    ``task_axes``: the arm's controlled pose components (:func:`restrict_orientation`).
    """
    want = _xyz(_select(program, task.name, "design"))
    values: list[np.ndarray | None] = []
    rotations: list[np.ndarray | None] = []
    for controller in CONTROLLERS:
        m = _select(measurements, task.name, controller)
        if not any(len(v) for v in m.values()):
            values.append(None)
            rotations.append(None)
            continue
        rotations.append(_xyz(m, ("rx_deg", "ry_deg", "rz_deg")) if "rx_deg" in m else None)
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
    table = _fill_unmeasured(values)
    if len(controlled_rotations(task_axes)) == 3 or task.name not in ("grid3d", "grid12"):
        return names, table
    return restrict_orientation(task.name, names, table, _fill_unmeasured(rotations), task_axes)


def _fill_unmeasured(rows: list[np.ndarray | None]) -> np.ndarray:
    """Rows stacked, NaN for the controllers not measured (None)."""
    like = next(r for r in rows if r is not None)  # the design controller is always measured
    return np.stack([np.full(like.shape, np.nan) if r is None else r for r in rows])


def restrict_orientation(
    task: str,
    names: list[tuple[str, str, bool]],
    values: np.ndarray,
    w_deg: np.ndarray,
    task_axes: tuple[int, ...],
) -> tuple[list[tuple[str, str, bool]], np.ndarray]:
    """Orientation indices of an arm that controls only some rotation components.

    ``w_deg`` (c, m, 3): measured rotation vectors (deg) of each point from the
    desired orientation, about the workspace axes, per controller. With ``c``
    the controlled rotation components of ``task_axes`` (a SCARA: Z, the only
    one its solver sets to 0):

    - ``grid3d``: the relative orientation at Vertex 4 is ``w4[c] - w1[c]``
      (desired 0: one orientation at every point); the other components are
      dropped (:func:`dropped_indices`).
    - ``grid12``: the absolute orientation error at a corner is ``|w_v[c]|``, the
      relative one ``|w_v[c] - w_1[c]|``, renamed ``..._orientation_error_z_deg``;
      dropped when no rotation is controlled.

    To first order these are the full indices' components; unlike the rotation
    composed from the full vectors they do not mix in the uncontrolled tilts
    (second order, ~1e-4° for a 0.2° fixture tilt), so they are exact when the
    controller is.
    """
    c = list(controlled_rotations(task_axes))
    letters = "".join(AXIS_LETTERS[i] for i in c)
    dropped = dropped_indices(task, task_axes)
    out_names, out_vals = [], []
    for k, (name, unit, signed) in enumerate(names):
        if name in dropped:
            continue
        v = values[:, k]
        if task == "grid3d" and name.startswith("relative_orientation_"):
            w = w_deg.reshape(len(w_deg), *GRID3D_SHAPE, 3)
            rel = w[:, -1, -1, 0] - w[:, 0, 0, 0]  # Vertex 4 (corner (nx, ny, 1)) - Vertex 1
            v = rel[:, AXIS_LETTERS.index(name.split("_")[2])]
        elif task == "grid12" and name.endswith("orientation_error_deg"):
            vertex = int(name[len("vertex") :].split("_")[0])
            wv = w_deg[:, vertex - 1][:, c]
            if "relative" in name:
                wv = wv - w_deg[:, 0][:, c]
            v = np.linalg.norm(wv, axis=-1)
            name = name.replace("orientation_error_deg", f"orientation_error_{letters}_deg")
        out_names.append((name, unit, signed))
        out_vals.append(v)
    return out_names, np.stack(out_vals, axis=1)
