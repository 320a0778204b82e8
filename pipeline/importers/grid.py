"""The cells of a table import, one row per pose: one file, several files joined by row,
stacked rows (``points_per_pose``, ``pose_column``), or a MATLAB file's variables.

A *block* is one source of columns: a delimited file or a ``.mat`` variable, its header
and its data rows. Blocks holding target columns are stacked when the map says so (k
rows per pose become one row of k sub-rows). The blocks' rows are then joined by
position (row i of each block is pose i): their counts must agree, and a mismatch is
refused in one line naming the file. A map column resolves to a position in the joined
row; a cell's error names its own file and line.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.numeric import NumberRows, numeric_rows

#: A cell: the text of a delimited file, or a number of a MATLAB variable.
CellValue = str | float


@dataclass(frozen=True)
class Block:
    """One source of columns.

    ``name`` names it in messages ("a.csv", "f.mat: variable P"), ``file`` is its file's
    name (a row's ``source_file``), ``header`` its column names (None: numbered), ``rows``
    its data rows as (line, cells), ``line`` the header's line."""

    name: str
    file: str
    header: list[str] | None
    rows: Sequence[tuple[int, list[CellValue]]]  # NumberRows: a plain numeric file's
    line: int = 1
    word: str = "line"  # what a row's number counts: a text file's line, a .mat row

    def column(self, col: str | int, what: str) -> int:
        """0-based index of a map column (header name or 1-based number) in this block."""
        src, header = self.name, self.header
        if isinstance(col, int):
            if header is not None and col > len(header):
                raise ImportFileError(
                    f"{src}: line {self.line}: no column {col} for {what}",
                    expected=f"a column number 1 to {len(header)}",
                    fix="correct the map",
                )
            return col - 1
        if header is None or col not in header:
            raise ImportFileError(
                f"{src}: line {self.line}: missing column {col!r} ({what})",
                expected="a column of the header" if header else "a header (map: header = true)",
                got=", ".join(header) if header else "no header",
                fix="correct the column name in the map, or add the column to the file",
            )
        at = [k + 1 for k, h in enumerate(header) if h == col]
        if len(at) > 1:
            raise ImportFileError(
                f"{src}: line {self.line}: column {col!r} ({what}) appears {len(at)} times in "
                f"the header (columns {', '.join(map(str, at[:-1]))} and {at[-1]})",
                expected="a column name the header holds once",
                fix=f"name the column by its number in the map (e.g. {at[-1]}), or rename it",
            )
        return at[0] - 1

    @property
    def width(self) -> int:
        """Columns of a row (the header's, else the widest row's)."""
        if self.header is not None:
            return len(self.header)
        if isinstance(self.rows, NumberRows):
            return int(self.rows.values.shape[1])
        return max((len(c) for _, c in self.rows), default=0)


def stacked(block: Block, k: int | None, pose_col: int | None) -> list[Block]:
    """``block``'s rows as poses of sub-rows: ``k`` consecutive rows per pose, or the rows
    sharing a value of column ``pose_col`` (in order of first appearance, ``k`` of each
    when given). One block per sub-row, each with one row per pose."""
    rows = block.rows
    if pose_col is None:
        assert k is not None
        if len(rows) % k:
            raise ImportFileError(
                f"{block.name}: {len(rows):,} rows, not a multiple of points_per_pose = {k} "
                f"({len(rows) % k} left over after {block.word} {rows[-1 - len(rows) % k][0]})",
                expected=f"{k} consecutive rows per pose",
                fix="complete or delete the last pose's rows, or correct points_per_pose",
            )
        groups = [rows[i : i + k] for i in range(0, len(rows), k)]
    else:
        by: dict[str, list[tuple[int, list[CellValue]]]] = {}
        for line, cells in rows:
            key = str(cells[pose_col]).strip() if pose_col < len(cells) else ""
            by.setdefault(key, []).append((line, cells))
        groups = list(by.values())
        k = k or len(groups[0])
        bad = [g for g in groups if len(g) != k]
        if bad:
            raise ImportFileError(
                f"{block.name}: {block.word} {bad[0][0][0]}: pose "
                f"{str(bad[0][0][1][pose_col]).strip()!r} "
                f"has {len(bad[0])} rows (pose_column)",
                expected=f"{k} rows per pose, one per [[targets]] of the file",
                fix="complete or delete the pose's rows",
            )
    return [
        Block(f"{block.name} (row {j + 1} of each pose)" if j else block.name, block.file,
              block.header, [g[j] for g in groups], block.line, block.word)
        for j in range(k)
    ]  # fmt: skip


@dataclass(frozen=True)
class Grid:
    """Blocks joined by row: ``rows[r]`` is pose r's cells (every block's, side by side),
    ``offsets[b]`` where block b's columns start, ``lines[r, b]`` its line of pose r."""

    blocks: tuple[Block, ...]
    offsets: tuple[int, ...]
    rows: Sequence[list[CellValue]]
    lines: np.ndarray  # (R, B) int

    def index(self, b: int, col: str | int, what: str) -> int:
        """The joined-row position of block ``b``'s column ``col``."""
        return self.offsets[b] + self.blocks[b].column(col, what)

    def place(self, k: int, r: int) -> str:
        """Where pose r's cell of joined column ``k`` is: "b.csv: line 7"."""
        b = int(np.searchsorted(self.offsets, k, side="right")) - 1
        return f"{self.blocks[b].name}: {self.blocks[b].word} {self.lines[r, b]}"

    def local(self, k: int) -> int:
        """Joined column ``k``'s 1-based number in its own block."""
        b = int(np.searchsorted(self.offsets, k, side="right")) - 1
        return k - self.offsets[b] + 1


def joined(blocks: list[Block]) -> Grid:
    """The blocks side by side, row i of each being pose i; differing row counts are
    refused in one line naming the file."""
    counts = [len(b.rows) for b in blocks]
    if len(set(counts)) > 1:
        k = next(i for i, c in enumerate(counts) if c != counts[0])
        raise ImportFileError(
            f"{blocks[k].name}: {counts[k]:,} rows, but {blocks[0].name} has {counts[0]:,}",
            expected="the same number of rows (poses) in every file joined by row: row i of "
            "each is pose i",
            fix="give files of the same poses, or delete the extra rows",
        )
    numbers = blocks[0].rows
    if len(blocks) == 1 and isinstance(numbers, NumberRows):  # numbers already
        return Grid((blocks[0],), (0,), numbers.values, numbers.lines[:, None])  # type: ignore[arg-type]
    if len(blocks) == 1:
        b = blocks[0]
        lines = np.array([line for line, _ in b.rows], np.int64)[:, None]
        return Grid((b,), (0,), [cells for _, cells in b.rows], lines)
    widths = [b.width for b in blocks]
    offsets = tuple(int(v) for v in np.concatenate([[0], np.cumsum(widths)[:-1]]))
    rows = []
    for parts in zip(*(b.rows for b in blocks), strict=True):
        cells: list[CellValue] = []
        for (_, c), w in zip(parts, widths, strict=True):
            cells += c[:w] + [""] * (w - len(c))  # a short row: its missing cells are empty
        rows.append(cells)
    lines = np.array([[line for line, _ in b.rows] for b in blocks], np.int64).T
    return Grid(tuple(blocks), offsets, rows, lines)


def delimited_block(
    path: Path,
    skip_rows: int,
    skip_lines: tuple[int, ...],
    header: bool,
    delimiter: str | None,
    decimal: str,
    numeric: bool = False,
) -> Block:
    """A delimited text file's block: its header (``header``) and its data rows after
    ``skip_rows`` lines, without blank lines and the lines of ``skip_lines``. ``numeric``:
    a plain numeric file is read by polars (:mod:`pipeline.importers.numeric`; the caller
    says that its map reads no text cell, stacks no rows and skips no line)."""
    from pipeline.importers.sscanss2 import csv_rows, editor_lines, read_text

    src = path.name
    if numeric and decimal == "." and not skip_lines:
        plain = numeric_rows(path, skip_rows, header, delimiter,
                             lambda lines: guessed_delimiter(lines, decimal))  # fmt: skip
        if plain is not None:
            return Block(src, src, plain[0], plain[1], skip_rows + 1)
    lines = editor_lines(read_text(path))[skip_rows:]
    delim = delimiter or guessed_delimiter(lines, decimal)
    reader = csv_rows(lines, src, skip_rows, delimiter=delim, skipinitialspace=True)
    names: list[str] | None = None
    hl = skip_rows + 1  # the header's line
    if header:
        names = [h.strip() for h in next(reader, (hl, []))[1]]
        reader = _no_wider(reader, names, src)
    skip = set(skip_lines)
    rows: list[tuple[int, list[CellValue]]] = [
        (line, fields)  # type: ignore[misc]
        for line, fields in reader
        if line not in skip and any(f.strip() for f in fields)
    ]
    return Block(src, src, names, rows, hl)


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


def guessed_delimiter(lines: list[str], decimal: str) -> str:
    """A delimiter guessed among , ; tab space (not ',' with decimal commas)."""
    candidates = ";\t " if decimal == "," else ",;\t "
    try:
        return csv.Sniffer().sniff("\n".join(lines[:20]), delimiters=candidates).delimiter
    except csv.Error:
        return candidates[0]


def matched(pattern: str | None, paths: list[Path], default: Path, what: str) -> Path:
    """The one given file a map's ``file`` names (its name, or a glob of it); ``default``
    when it names none."""
    from fnmatch import fnmatchcase

    if pattern is None:
        return default
    hits = [p for p in paths if fnmatchcase(p.name, pattern)]
    if len(hits) != 1:
        raise ImportFileError(
            f"{what}: file = {pattern!r} names {len(hits)} of the given files",
            expected="exactly one of " + ", ".join(p.name for p in paths),
            got=", ".join(p.name for p in hits) or "none",
            fix="give the file on the command line, or correct the map's file",
        )
    return hits[0]
