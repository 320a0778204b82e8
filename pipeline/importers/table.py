"""A generic delimited table of measured points and joint readings, read with a map file.

The rows form joint sweeps (a sweep column, ``infer``, or ``[[sweeps.select]]``) or,
with ``sweep = "poses"`` in the map, a pose set: every row a configuration of sweep
``poses`` (a seeded fraction of them validation configurations, ``[check]``), no sweep
inference. Per-point σ comes from columns or one stated value; numbers may use a
decimal comma (``decimal = ","``)."""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.mapping import ImportMap, TargetColumns
from pipeline.importers.rows import (
    ANGLE_DEG,
    LENGTH_CM,
    MeasuredRows,
    readings_in_boundary_units,
    unit_factor,
)
from pipeline.importers.sscanss2 import csv_rows, editor_lines, read_text
from pipeline.importers.sweeps import infer_sweeps, pose_set, select_sweeps, tolerances
from pipeline.robots.description import RobotDescription
from pipeline.stages.recording import CHECK_SWEEP

FORMAT = "table"
INFER = "infer"
_MISSING = ("", "nan", "na", "null")

#: A cell parser: (fields, 0-based column, file line, what the column is) -> number.
Cell = Callable[[list[str], int, int, str], float]


def _index(col: str | int, header: list[str] | None, src: str, line: int, what: str) -> int:
    """0-based index of a map column (header name or 1-based number)."""
    if isinstance(col, int):
        if header is not None and col > len(header):
            raise ImportFileError(
                f"{src}: line {line}: no column {col} for {what}",
                expected=f"a column number 1 to {len(header)}",
                fix="correct the map",
            )
        return col - 1
    if header is None or col not in header:
        raise ImportFileError(
            f"{src}: line {line}: missing column {col!r} ({what})",
            expected="a column of the header" if header else "a header (map: header = true)",
            got=", ".join(header) if header else "no header",
            fix="correct the column name in the map, or add the column to the file",
        )
    at = [k + 1 for k, h in enumerate(header) if h == col]
    if len(at) > 1:
        raise ImportFileError(
            f"{src}: line {line}: column {col!r} ({what}) appears {len(at)} times in the header "
            f"(columns {', '.join(map(str, at[:-1]))} and {at[-1]})",
            expected="a column name the header holds once",
            fix=f"name the column by its number in the map (e.g. {at[-1]}), or rename it",
        )
    return at[0] - 1


def _cell_reader(src: str, decimal: str) -> Cell:
    """Parse a cell as a number (NaN when empty or "nan"); with a decimal comma, "0,5" is
    one half and a cell holding a '.' (a thousands separator?) is refused."""

    def cell(cells: list[str], k: int, line: int, what: str) -> float:
        if k >= len(cells):
            raise ImportFileError(
                f"{src}: line {line}: {len(cells)} columns, no column {k + 1} ({what})",
                expected=f"at least {k + 1} columns",
                fix="complete the row (a missing column?) or list it in the map's skip_lines",
            )
        text = cells[k].strip()
        if text.lower() in _MISSING:
            return float("nan")
        if decimal == ",":
            if "." in text:
                raise ImportFileError(
                    f"{src}: line {line}: column {k + 1} ({what}) holds a '.' in a file with "
                    "decimal commas",
                    expected='numbers like 0,5 (map: decimal = ",")',
                    got=repr(text),
                    fix='remove the thousands separators, or set decimal = "." in the map',
                )
            text = text.replace(",", ".")
        try:
            return float(text)
        except ValueError:
            raise ImportFileError(
                f"{src}: line {line}: column {k + 1} ({what}) is not a number",
                got=repr(text),
                fix="write a decimal number, or list the row in the map's skip_lines",
            ) from None

    return cell


def _delimiter(imap: ImportMap, lines: list[str]) -> str:
    """The map's delimiter, else guessed among , ; tab space (not ',' with decimal commas)."""
    if imap.delimiter is not None:
        return imap.delimiter
    candidates = ";\t " if imap.decimal == "," else ",;\t "
    try:
        return csv.Sniffer().sniff("\n".join(lines[:20]), delimiters=candidates).delimiter
    except csv.Error:
        return candidates[0]


def read_table(path: Path, imap: ImportMap, robot: RobotDescription) -> MeasuredRows:
    """Parse the table with its map into rows (deg / cm) with their sweeps assigned."""
    src, mname = path.name, imap.name
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
    lines = editor_lines(read_text(path))[imap.skip_rows :]
    reader = csv_rows(lines, src, imap.skip_rows, delimiter=_delimiter(imap, lines),
                      skipinitialspace=True)  # fmt: skip
    header: list[str] | None = None
    hl = imap.skip_rows + 1  # the header's line
    if imap.header:
        header = [h.strip() for h in next(reader, (hl, []))[1]]
        reader = _no_wider(reader, header, src)
    length = unit_factor(imap.length_unit, LENGTH_CM, "length", f"{mname}: length_unit")
    # the tool target first: its id is plan.tool_target, its orientation the recorded one
    targets = sorted(imap.targets, key=lambda t: t.id != (imap.tool_target or imap.targets[0].id))
    cols = {t.id: [_index(c, header, src, hl, f"target {t.id} {a}")
                   for c, a in zip((t.x, t.y, t.z), "xyz", strict=True)]
            for t in targets}  # fmt: skip
    scols = {t.id: [_index(c, header, src, hl, f"target {t.id} σ {a}")
                    for c, a in zip(_sigma_columns(t), "xyz", strict=True)]
             for t in targets if t.sigma is not None or t.sigma_xyz is not None}  # fmt: skip
    jcols = [_index(j.column, header, src, hl, f"joint {k + 1}")
             for k, j in enumerate(imap.joints)]  # fmt: skip
    ocols = []
    if imap.orientation is not None:
        names = ("rx", "ry", "rz")
        ocols = [_index(c, header, src, hl, f"orientation {a}")
                 for c, a in zip(imap.orientation.columns, names, strict=True)]  # fmt: skip
    pcol = None
    if imap.payload_column is not None:
        pcol = _index(imap.payload_column, header, src, hl, "payload")
    scol = None
    if imap.sweep_column not in (None, INFER):
        scol = _index(imap.sweep_column, header, src, hl, "sweep")  # type: ignore[arg-type]
    cell = _cell_reader(src, imap.decimal)
    where, q, sweep, angles, payload = [], [], [], [], []  # type: ignore[var-annotated]
    pts = {t: [] for t in cols}  # type: ignore[var-annotated]
    sig = {t: [] for t in scols}  # type: ignore[var-annotated]
    for line, fields in reader:
        if not any(f.strip() for f in fields) or line in imap.skip_lines:
            continue
        where.append(f"line {line}")
        q.append([cell(fields, k, line, f"joint {j + 1}") for j, k in enumerate(jcols)])
        for t, c in cols.items():
            pts[t].append([cell(fields, k, line, f"target {t}") * length for k in c])
        for t, c in scols.items():
            sig[t].append([cell(fields, k, line, f"target {t} σ") * length for k in c])
        angles.append([cell(fields, k, line, "orientation") for k in ocols])
        if pcol is not None:
            payload.append(_payload_cell(cell(fields, pcol, line, "payload"), src, line))
        if scol is not None:
            sweep.append(_sweep_cell(fields, scol, src, line, robot.n_joints))
    if not where:
        raise ImportFileError(f"{src}: no rows", fix="check skip_rows and header in the map")
    units = [j.unit for j in imap.joints]
    qq = readings_in_boundary_units(np.array(q), units, robot, f"{mname}: [[joints]] unit")
    rows = MeasuredRows(
        path, tuple(where), np.array(sweep or [0] * len(where), np.int64), qq,
        {t: np.array(v, float) for t, v in pts.items()},
        orientation_wxyz=_quaternions(np.array(angles, float), imap),
        sigma=_sigmas(rows_sigma=sig, ids=list(cols), n=len(where)),
        orientation_sigma_deg=None if imap.orientation is None else imap.orientation.sigma_deg,
        payload_kg=np.array(payload, float) if pcol is not None else (
            None if imap.payload_kg is None else np.full(len(where), float(imap.payload_kg))
        ),
    ).with_sigma(imap.sigma_cm)  # fmt: skip
    if imap.poses:
        return pose_set(rows, imap)
    tol = tolerances(imap, robot).held
    if imap.select:
        return select_sweeps(rows, imap, robot, tol)
    if scol is None:
        if not np.isfinite(qq).all():
            bad = np.flatnonzero(~np.isfinite(qq).all(axis=1))[0]
            raise ImportFileError(
                f"{src}: {where[bad]}: a joint reading is missing or not a number (NaN)",
                expected="finite joint readings in every row",
                fix="delete the row, or list it in the map's skip_lines",
            )
        rows = replace(rows, sweep=infer_sweeps(rows, robot, tol))  # a wrap is a change
    return _unwrapped(rows, imap, robot)


def _no_wider(
    reader: Iterator[tuple[int, list[str]]], header: list[str], src: str
) -> Iterator[tuple[int, list[str]]]:
    """The rows of ``reader``, a row with more non-empty cells than the header has columns
    refused naming its line (its cells would be read shifted: a delimiter too many, or a
    decimal comma in a comma-separated file); empty cells past the header (a trailing
    delimiter) are allowed."""
    for line, fields in reader:
        extra = [f for f in fields[len(header) :] if f.strip()]
        if extra:
            raise ImportFileError(
                f"{src}: line {line}: {len(fields)} cells for the header's {len(header)} columns",
                expected="at most one cell per header column",
                got=f"extra cells {', '.join(repr(f) for f in extra[:3])}",
                fix="check the delimiter and decimal mark in the row (and the map's "
                "delimiter / decimal), or delete the row",
            )
        yield line, fields


def _payload_cell(kg: float, src: str, line: int) -> float:
    """A payload cell (kg), refused in one line unless finite, >= 0 and <= 10,000 kg."""
    if not (math.isfinite(kg) and 0.0 <= kg <= 10_000.0):
        raise ImportFileError(
            f"{src}: line {line}: payload {kg:g} kg",
            expected="a payload from 0 to 10000 kg (payload_column)",
            got=f"{kg:g}",
            fix="correct the cell, or skip the line (skip_lines)",
        )
    return kg


def _sigma_columns(t: TargetColumns) -> tuple[str | int, str | int, str | int]:
    """The σ columns of x, y, z: one per axis, or the one σ column three times."""
    if t.sigma_xyz is not None:
        return t.sigma_xyz
    assert t.sigma is not None  # the caller asks only for targets with σ columns
    return (t.sigma, t.sigma, t.sigma)


def _sigmas(
    rows_sigma: dict[str, list[list[float]]], ids: list[str], n: int
) -> dict[str, np.ndarray] | None:
    """Each target's σ of x, y, z (n, 3) cm from its columns, or none (the map's stated σ:
    :meth:`MeasuredRows.with_sigma`)."""
    if not rows_sigma:
        return None
    return {t: np.array(rows_sigma[t], float) if t in rows_sigma else np.full((n, 3), np.nan)
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


def _sweep_cell(fields: list[str], k: int, src: str, line: int, n: int) -> int:
    text = fields[k].strip() if k < len(fields) else ""
    if text == "check":
        return CHECK_SWEEP
    if text.isdigit() and 1 <= int(text) <= n:
        return int(text)
    raise ImportFileError(
        f"{src}: line {line}: sweep column holds {text!r}",
        expected=f"a joint number 1 to {n}, or 'check' for a validation configuration",
        fix='correct the sweep column, or use column = "infer" in the map',
    )
