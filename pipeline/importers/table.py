"""A generic delimited table of measured points and joint readings, read with a map file.

The rows form joint sweeps (a sweep column, ``infer``, or ``[[sweeps.select]]``) or,
with ``sweep = "poses"`` in the map, a pose set: every row a configuration of sweep
``poses`` (a seeded fraction of them validation configurations, ``[check]``), no sweep
inference. Per-point σ comes from columns or one stated value; numbers may use a
decimal comma (``decimal = ","``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.fixed import registered
from pipeline.importers.grid import Block, CellValue, Grid
from pipeline.importers.layout import Columns, columns, delimited_loader
from pipeline.importers.mapping import ImportMap
from pipeline.importers.missing import sigma_floored, without_missing
from pipeline.importers.rows import (
    ANGLE_DEG,
    LENGTH_CM,
    MeasuredRows,
    Places,
    concat_rows,
    readings_in_boundary_units,
    unit_factor,
)
from pipeline.importers.sweeps import (
    held_out_marked,
    infer_sweeps,
    pose_set,
    select_sweeps,
    tolerances,
)
from pipeline.robots.description import RobotDescription
from pipeline.stages.recording import CHECK_SWEEP, POSES_SWEEP

FORMAT = "table"
INFER = "infer"
_MISSING = ("", "nan", "na", "null")

#: A cell parser: (cells, 0-based joined column, pose row, what the column is) -> number.
Cell = Callable[[list[CellValue], int, int, str], float]
#: A file's blocks of columns: (path, the variables the map names) -> blocks by variable.
Loader = Callable[[Path, set[str | None]], dict[str | None, Block]]
#: A ``.mat`` column ("Q:2") -> its variable and its column there.
Variable = Callable[[str | int], tuple[str | None, str | int]]


def cell_reader(grid: Grid, decimal: str) -> Cell:
    """Parse a cell as a number (NaN when empty or "nan"; a ``.mat`` number as it is); with
    a decimal comma, "0,5" is one half and a cell holding a '.' (a thousands separator?) is
    refused. Errors name the cell's own file and line."""

    def cell(cells: list[CellValue], k: int, r: int, what: str) -> float:
        if k >= len(cells):
            raise ImportFileError(
                f"{grid.place(k, r)}: {len(cells)} columns, no column {grid.local(k)} ({what})",
                expected=f"at least {grid.local(k)} columns",
                fix="complete the row (a missing column?) or list it in the map's skip_lines",
            )
        value = cells[k]
        if isinstance(value, float):
            return value
        text = value.strip()
        if text.lower() in _MISSING:
            return float("nan")
        if decimal == ",":
            if "." in text:
                raise ImportFileError(
                    f"{grid.place(k, r)}: column {grid.local(k)} ({what}) holds a '.' in a file "
                    "with decimal commas",
                    expected='numbers like 0,5 (map: decimal = ",")',
                    got=repr(text),
                    fix='remove the thousands separators, or set decimal = "." in the map',
                )
            text = text.replace(",", ".")
        try:
            return float(text)
        except ValueError:
            raise ImportFileError(
                f"{grid.place(k, r)}: column {grid.local(k)} ({what}) is not a number",
                got=repr(text),
                fix="write a decimal number, or list the row in the map's skip_lines",
            ) from None

    return cell


def read_table(
    paths: Path | list[Path],
    imap: ImportMap,
    robot: RobotDescription,
    loader: Loader | None = None,
    variable: Variable | None = None,
) -> MeasuredRows:
    """Parse the file(s) with their map into rows (deg / cm) with their sweeps assigned:
    each file alike, one after the other, or the files joined by row (a map's ``file``
    keys). ``loader`` and ``variable``: a ``.mat`` file's blocks
    (:mod:`pipeline.importers.matfile`); default a delimited file's."""
    mname = imap.name
    paths = [paths] if isinstance(paths, Path) else paths
    if len(imap.joints) != robot.n_joints:
        raise ImportFileError(
            f"{mname}: {len(imap.joints)} [[joints]] for {robot.n_joints} joints of {robot.name}",
            expected="one [[joints]] per joint of the robot, base to tip",
            fix="complete the map's [[joints]]",
        )
    if not imap.targets:
        raise ImportFileError(
            f"{mname}: no [[targets]]", expected="x, y, z columns of at least one target",
            fix="add a [[targets]] table (docs/import.md)",
        )  # fmt: skip
    if imap.skip_lines and (len(paths) > 1 or loader is not None):
        raise ImportFileError(
            f"{mname}: skip_lines with {'a .mat file' if loader else f'{len(paths)} files'}: "
            "its line numbers name no one file",
            expected="skip_lines with one delimited file",
            fix="leave the rows' cells empty (dropped and counted), or hold them out by "
            "check.rows; or import one file",
        )
    load = loader or delimited_loader(imap)
    scol = imap.sweep_column if imap.sweep_column not in (None, INFER) else None
    groups = [paths] if imap.joined else [[p] for p in paths]
    rows = concat_rows([_parsed(columns(g, imap, load, variable, scol), g[0], imap, robot)
                        for g in groups])  # fmt: skip
    rows = held_out_marked(rows, imap, paths)
    rows = sigma_floored(without_missing(rows, imap, imap.strict), imap)
    rows = registered(rows, imap)  # fixed targets: each pose in one tracker frame
    return assigned(rows, imap, robot, scol is not None)


def _parsed(cols: Columns, path: Path, imap: ImportMap, robot: RobotDescription) -> MeasuredRows:
    """One grid's rows in armsig's units (sweeps from a sweep column, else 0)."""
    grid, mname = cols.grid, imap.name
    length = unit_factor(imap.length_unit, LENGTH_CM, "length", f"{mname}: length_unit")
    what = [*((k, f"joint {j + 1}") for j, k in enumerate(cols.joints)),
            *((k, f"target {t}") for t, c in cols.targets.items() for k in c),
            *((k, f"target {t} σ") for t, c in cols.sigmas.items() for k in c),
            *((k, "orientation") for k in cols.orientation),
            *([] if cols.payload is None else [(cols.payload, "payload")])]  # fmt: skip
    first: dict[int, str] = {}
    for k, w in what:
        first.setdefault(k, w)  # a column read twice is named by its first use
    num = _numbers(grid, list(first.items()), imap.decimal)

    def stack(ks: list[int]) -> np.ndarray:
        return np.column_stack([num[k] for k in ks]) if ks else np.zeros((len(grid.rows), 0))

    q = stack(cols.joints)
    pts = {t: stack(c) * length for t, c in cols.targets.items()}
    sig = {t: stack(c) * length for t, c in cols.sigmas.items()}
    angles = stack(cols.orientation)
    payload = None
    if cols.payload is not None:
        payload = num[cols.payload]
        bad = np.flatnonzero(~(np.isfinite(payload) & (payload >= 0.0) & (payload <= 10_000.0)))
        if len(bad):
            _payload_cell(float(payload[bad[0]]), grid.place(cols.payload, int(bad[0])))
    sweep = (
        []
        if cols.sweep is None
        else [_sweep_cell(f, cols.sweep, grid, r, robot.n_joints) for r, f in enumerate(grid.rows)]
    )
    held = [] if cols.check is None else [
        _held_cell(f, cols.check, grid, r) for r, f in enumerate(grid.rows)]  # fmt: skip
    block = grid.blocks[0]
    if not len(grid.rows):
        raise ImportFileError(f"{block.name}: no rows", fix="check skip_rows and header in the map")
    n = len(grid.rows)
    units = [j.unit for j in imap.joints]
    qq = readings_in_boundary_units(q, units, robot, f"{mname}: [[joints]] unit")
    sw = np.array(sweep, np.int64) if sweep else np.zeros(n, np.int64)
    if held:
        sw = np.where(held, CHECK_SWEEP, POSES_SWEEP)
    return MeasuredRows(
        path, Places(block.word, grid.lines[:, 0].copy()), sw, qq,
        pts,
        orientation_wxyz=_quaternions(angles, imap),
        sigma=_sigmas(rows_sigma=sig, ids=list(cols.targets), n=n),
        orientation_sigma_deg=None if imap.orientation is None else imap.orientation.sigma_deg,
        payload_kg=payload if payload is not None else (
            None if imap.payload_kg is None else np.full(n, float(imap.payload_kg))
        ),
        files=(block.file,) * n,
        lines=grid.lines[:, 0].copy(),
    ).with_sigma(imap.sigma_cm)  # fmt: skip


def assigned(
    rows: MeasuredRows, imap: ImportMap, robot: RobotDescription, sweep_column: bool
) -> MeasuredRows:
    """The rows' sweeps: the pose set (with its held-out rows), a selection, the sweep
    column's (already read), or inferred from the joints (file order)."""
    if imap.poses:
        return pose_set(rows, imap)
    tol = tolerances(imap, robot).held
    if imap.select:
        return select_sweeps(rows, imap, robot, tol)
    if not sweep_column:
        qq = rows.q
        if not np.isfinite(qq).all():
            bad = int(np.flatnonzero(~np.isfinite(qq).all(axis=1))[0])
            raise ImportFileError(
                f"{rows.at(bad)}: a joint reading is missing or not a number (NaN)",
                expected="finite joint readings in every row",
                fix="delete the row, or list it in the map's skip_lines",
            )
        rows = replace(rows, sweep=infer_sweeps(rows, robot, tol))  # a wrap is a change
    return _unwrapped(rows, imap, robot)


def _payload_cell(kg: float, place: str) -> float:
    """A payload cell (kg), refused in one line unless finite, >= 0 and <= 10,000 kg."""
    if not (math.isfinite(kg) and 0.0 <= kg <= 10_000.0):
        raise ImportFileError(
            f"{place}: payload {kg:g} kg",
            expected="a payload from 0 to 10000 kg (payload_column)",
            got=f"{kg:g}",
            fix="correct the cell, or skip the line (skip_lines)",
        )
    return kg


def _numbers(grid: Grid, ks: list[tuple[int, str]], decimal: str) -> dict[int, np.ndarray]:
    """The numbers of the joined columns ``ks`` (position, what it is; NaN where empty or
    "nan"). A column whose
    text numpy reads as it is (or, with decimal commas, once its commas are points and it
    holds no '.') is converted at once, the same doubles as Python's ``float``; otherwise
    every cell is read in row order (:func:`cell_reader`), so that the first bad cell
    of the file is the one refused."""
    if isinstance(grid.rows, np.ndarray):  # a plain numeric file (importers/numeric.py)
        if all(k < grid.rows.shape[1] for k, _ in ks):
            return {k: grid.rows[:, k] for k, _ in ks}
        return _numbers_by_cell(grid, ks, decimal)
    out: dict[int, np.ndarray] = {}
    for k, _ in ks:
        try:
            cells = [c[k] for c in grid.rows]
            if decimal == ",":
                if any("." in c for c in cells if isinstance(c, str)):
                    raise ValueError  # refused, naming the cell, by the cell reader
                cells = [c.replace(",", ".") if isinstance(c, str) else c for c in cells]
            out[k] = np.array(cells, dtype=float)
        except (ValueError, IndexError, TypeError):
            return _numbers_by_cell(grid, ks, decimal)
    return out


def _numbers_by_cell(grid: Grid, ks: list[tuple[int, str]], decimal: str) -> dict[int, np.ndarray]:
    """:func:`_numbers` read cell by cell in row order: a bad cell is refused naming its
    file, line and column."""
    cell = cell_reader(grid, decimal)
    values = [[cell(f, k, r, w) for k, w in ks] for r, f in enumerate(grid.rows)]
    arr = np.array(values, float).reshape(len(grid.rows), len(ks))
    return {k: arr[:, j] for j, (k, _) in enumerate(ks)}


def _sigmas(
    rows_sigma: dict[str, np.ndarray], ids: list[str], n: int
) -> dict[str, np.ndarray] | None:
    """Each target's σ of x, y, z (n, 3) cm from its columns, or none (the map's stated σ:
    :meth:`MeasuredRows.with_sigma`)."""
    if not rows_sigma:
        return None
    return {t: rows_sigma[t] if t in rows_sigma else np.full((n, 3), np.nan)
            for t in ids}  # fmt: skip


def _quaternions(angles: np.ndarray, imap: ImportMap) -> np.ndarray | None:
    """Unit quaternions (R, 4) w, x, y, z of the map's Euler angles (R, 3), or None."""
    if imap.orientation is None:
        return None
    from scipy.spatial.transform import Rotation

    o = imap.orientation
    deg = np.deg2rad(angles * unit_factor(o.unit, ANGLE_DEG, "angle", f"{imap.name}: orientation"))
    out = np.full((len(angles), 4), np.nan)
    ok = np.isfinite(deg).all(axis=1)  # NaN angles: NaN quaternions, refused with the row
    if ok.any():
        out[ok] = Rotation.from_euler(o.convention, deg[ok]).as_quat()[:, [3, 0, 1, 2]]
    return out


def _unwrapped(rows: MeasuredRows, imap: ImportMap, robot: RobotDescription) -> MeasuredRows:
    """The swept joint's readings of each sweep with 360 deg jumps removed (file order),
    for the joints whose map says ``unwrap``."""
    q = rows.q.copy()
    for j, spec in enumerate(imap.joints):
        if spec.unwrap and not robot.joints[j].prismatic:
            sel = np.flatnonzero(rows.sweep == j + 1)
            q[sel, j] = np.unwrap(q[sel, j], period=360.0)
    return replace(rows, q=q)


def _sweep_cell(fields: list[CellValue], k: int, grid: Grid, r: int, n: int) -> int:
    text = str(fields[k]).strip() if k < len(fields) else ""
    if text == "check":
        return CHECK_SWEEP
    if text.isdigit() and 1 <= int(text) <= n:
        return int(text)
    raise ImportFileError(
        f"{grid.place(k, r)}: sweep column holds {text!r}",
        expected=f"a joint number 1 to {n}, or 'check' for a validation configuration",
        fix='correct the sweep column, or use column = "infer" in the map',
    )


_TRUE = ("true", "1", "yes", "1.0")
_FALSE = ("false", "0", "no", "0.0", "")


def _held_cell(fields: list[CellValue], k: int, grid: Grid, r: int) -> bool:
    """A ``check.column`` cell: true (held out) or false."""
    text = str(fields[k]).strip().lower() if k < len(fields) else ""
    if text in _TRUE or text in _FALSE:
        return text in _TRUE
    raise ImportFileError(
        f"{grid.place(k, r)}: check column holds {text!r}",
        expected="true or false (1 or 0): the row held out or not",
        fix="correct the cell, or name the held-out rows by check.rows",
    )
