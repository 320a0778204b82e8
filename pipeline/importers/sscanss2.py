"""SScanSS-2's calibration text: seven columns, tab- or comma-separated, no header.

``joint_index x y z joint_value type home`` (SScanSS-2 ``docs/calibration.rst``):
x, y, z in mm; the joint value in deg (revolute) or mm (prismatic), the reading at
which the point was measured; ``home`` the value this joint holds while the others
move. Each joint moves alone from home, so a row of joint i reads home on every
other joint. Every row measures the same end-effector point (target ``ee``).
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ImportFileError, one_line
from pipeline.importers.rows import LENGTH_CM, MeasuredRows
from pipeline.robots.description import RobotDescription

FORMAT = "sscanss2"
COLUMNS = ("joint index", "x", "y", "z", "joint value", "type", "home")
TARGET = "ee"


def read_text(path: Path) -> str:
    """A text file's content (UTF-8, a leading byte-order mark dropped: Excel's "CSV
    UTF-8" writes one); an unreadable file is refused."""
    try:
        return path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportFileError(
            f"cannot read {path}", got=str(exc), fix="check the path and that it is a text file"
        ) from exc


#: The line ends an editor (and ``csv``) knows. ``str.splitlines`` also ends a line at a
#: form feed, a vertical tab, U+001C-U+001E, NEL, U+2028 and U+2029, which would number
#: the lines after one differently from what the user sees (issue 32: ``skip_lines``).
_LINE_END = re.compile(r"\r\n|\r|\n")


def editor_lines(text: str) -> list[str]:
    """``text``'s lines as an editor numbers them: only \\n, \\r\\n and \\r end a line
    (line k of the file is item k - 1)."""
    lines = _LINE_END.split(text)
    return lines[:-1] if lines and lines[-1] == "" else lines


def csv_rows(
    lines: list[str], src: str, offset: int = 0, **fmt: Any
) -> Iterator[tuple[int, list[str]]]:
    """``(line number, fields)`` of each record of ``lines`` (``csv.reader`` with ``fmt``;
    numbers from ``offset`` + 1); a record csv cannot read (a field over its size limit)
    is refused naming its line."""
    reader = csv.reader(lines, **fmt)
    while True:
        try:
            fields = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            raise ImportFileError(
                f"{src}: line {reader.line_num + offset}: {one_line(str(exc), 100)}",
                expected=f"fields of at most {csv.field_size_limit()} characters",
                fix="check the line (a quote left open joins the lines after it), or delete it",
            ) from None
        yield reader.line_num + offset, fields


def _number(text: str, src: str, line: int, col: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ImportFileError(
            f"{src}: line {line}: column '{col}' is not a number",
            got=repr(text),
            fix="write a decimal number (SScanSS-2's 7-column format)",
        ) from None


def read_sscanss2(path: Path, robot: RobotDescription) -> tuple[MeasuredRows, np.ndarray]:
    """Parse the file; the rows (deg / cm) and the home readings, shape (n,)."""
    text = read_text(path)
    src = path.name
    delimiter = "\t" if "\t" in text else ","
    n = robot.n_joints
    where, joint, value, xyz = [], [], [], []
    home: dict[int, tuple[float, int]] = {}
    for line, fields in csv_rows(editor_lines(text), src, delimiter=delimiter):
        cells = [f.strip() for f in fields]
        if not any(cells):
            continue
        if len(cells) != len(COLUMNS):
            raise ImportFileError(
                f"{src}: line {line}: {len(cells)} columns",
                expected=f"{len(COLUMNS)}: {', '.join(COLUMNS)}",
                fix="complete the row (a missing column?) or delete it",
            )
        j = _number(cells[0], src, line, COLUMNS[0])
        if not (1 <= j <= n and j == int(j)):  # NaN and ±inf first: int() refuses them
            raise ImportFileError(
                f"{src}: line {line}: joint index {cells[0]} names no joint of {robot.name}",
                expected=f"1 to {n}",
                fix="check the robot description (--robot) or the joint index",
            )
        spec = robot.joints[int(j) - 1]
        if cells[5] != spec.type:
            raise ImportFileError(
                f"{src}: line {line}: joint {int(j)} is {cells[5]!r} in the file but "
                f"{spec.type!r} ({spec.name}) in the robot description",
                expected=spec.type,
                fix="use the robot description of this machine, or correct the type column",
            )
        scale = LENGTH_CM["mm"] if spec.prismatic else 1.0
        h = _number(cells[6], src, line, COLUMNS[6]) * scale
        first = home.setdefault(int(j), (h, line))
        if h != first[0]:
            raise ImportFileError(
                f"{src}: line {line}: joint {int(j)} has home {cells[6]}, but {first[0] / scale:g} "
                f"on line {first[1]}",
                expected="one home value per joint",
                fix="correct the home column",
            )
        where.append(f"line {line}")
        joint.append(int(j))
        value.append(_number(cells[4], src, line, COLUMNS[4]) * scale)
        xyz.append([_number(cells[c], src, line, COLUMNS[c]) * LENGTH_CM["mm"] for c in (1, 2, 3)])
    if not where:
        raise ImportFileError(f"{src}: no rows", expected="SScanSS-2's 7-column rows")
    home_q = np.array([home.get(j + 1, (0.0, 0))[0] for j in range(n)])
    sweep = np.array(joint)
    q = np.tile(home_q, (len(where), 1))
    q[np.arange(len(where)), sweep - 1] = value
    rows = MeasuredRows(path, tuple(where), sweep, q, {TARGET: np.array(xyz, float)})
    return rows, home_q
