"""A generic delimited table of measured points and joint readings, read with a map file."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.mapping import ImportMap
from pipeline.importers.rows import LENGTH_CM, MeasuredRows, readings_in_boundary_units, unit_factor
from pipeline.importers.sscanss2 import read_text
from pipeline.importers.sweeps import infer_sweeps, select_sweeps, tolerance
from pipeline.robots.description import RobotDescription
from pipeline.stages.recording import CHECK_SWEEP

FORMAT = "table"
INFER = "infer"


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
    return header.index(col)


def _cell(cells: list[str], k: int, src: str, line: int, what: str) -> float:
    if k >= len(cells):
        raise ImportFileError(
            f"{src}: line {line}: {len(cells)} columns, no column {k + 1} ({what})",
            expected=f"at least {k + 1} columns",
            fix="complete the row (a missing column?) or list it in the map's skip_lines",
        )
    text = cells[k].strip()
    if text == "" or text.lower() in ("nan", "na", "null"):
        return float("nan")
    try:
        return float(text)
    except ValueError:
        raise ImportFileError(
            f"{src}: line {line}: column {k + 1} ({what}) is not a number",
            got=repr(text),
            fix="write a decimal number, or list the row in the map's skip_lines",
        ) from None


def read_table(path: Path, imap: ImportMap, robot: RobotDescription) -> MeasuredRows:
    """Parse the table with its map into rows (deg / cm) with their sweeps assigned."""
    src = path.name
    mname = imap.path.name if imap.path else "map"
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
    lines = read_text(path).splitlines()[imap.skip_rows :]
    delimiter = imap.delimiter
    if delimiter is None:
        try:
            delimiter = csv.Sniffer().sniff("\n".join(lines[:20]), delimiters=",;\t ").delimiter
        except csv.Error:
            delimiter = ","
    reader = csv.reader(lines, delimiter=delimiter, skipinitialspace=True)
    header: list[str] | None = None
    header_line = imap.skip_rows + 1
    if imap.header:
        header = [h.strip() for h in next(reader, [])]
    length = unit_factor(imap.length_unit, LENGTH_CM, "length", f"{mname}: length_unit")
    cols = {
        t.id: [_index(c, header, src, header_line, f"target {t.id} {a}")
               for c, a in zip((t.x, t.y, t.z), "xyz", strict=True)]
        for t in imap.targets
    }  # fmt: skip
    jcols = [_index(j.column, header, src, header_line, f"joint {k + 1}")
             for k, j in enumerate(imap.joints)]  # fmt: skip
    scol = None
    if imap.sweep_column not in (None, INFER):
        scol = _index(imap.sweep_column, header, src, header_line, "sweep")  # type: ignore[arg-type]
    where, q, pts, sweep = [], [], {t: [] for t in cols}, []  # type: ignore[var-annotated]
    for fields in reader:
        line = reader.line_num + imap.skip_rows
        if not any(f.strip() for f in fields) or line in imap.skip_lines:
            continue
        where.append(f"line {line}")
        q.append([_cell(fields, k, src, line, f"joint {j + 1}") for j, k in enumerate(jcols)])
        for t, c in cols.items():
            pts[t].append([_cell(fields, k, src, line, f"target {t}") * length for k in c])
        if scol is not None:
            sweep.append(_sweep_cell(fields, scol, src, line, robot.n_joints))
    if not where:
        raise ImportFileError(f"{src}: no rows", fix="check skip_rows and header in the map")
    units = [j.unit for j in imap.joints]
    qq = readings_in_boundary_units(np.array(q), units, robot, f"{mname}: [[joints]] unit")
    rows = MeasuredRows(
        path, tuple(where), np.array(sweep or [0] * len(where), np.int64), qq,
        {t: np.array(v, float) for t, v in pts.items()},
    )  # fmt: skip
    tol = tolerance(imap, robot)
    if imap.select:
        return select_sweeps(rows, imap, tol)
    if scol is None:
        if not np.isfinite(qq).all():
            bad = np.flatnonzero(~np.isfinite(qq).all(axis=1))[0]
            raise ImportFileError(
                f"{src}: {where[bad]}: a joint reading is missing or not a number (NaN)",
                expected="finite joint readings in every row",
                fix="delete the row, or list it in the map's skip_lines",
            )
        rows = replace(rows, sweep=infer_sweeps(rows, tol))  # a wrap is a change: it infers
    return _unwrapped(rows, imap, robot)


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
