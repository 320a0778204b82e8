"""A plain numeric delimited file read at once with polars' CSV reader (issue 45).

Python's ``csv`` module and ``float`` take ~8 s for a million rows of nine numbers;
polars parses them in a fraction of a second to the same doubles (both round each
decimal to the nearest double). Only a plain file is read this way: no quote, no lone
carriage return, no blank line, not space-separated, every cell of every row a number
(``nan`` and ``inf`` included) and every row as wide as the first (or the header). Anything
else returns None, and the ``csv`` reader reads the file as before, with every refusal and
its message (a short row, an empty cell, a text, a row too wide).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import overload

import numpy as np

_BOM = b"\xef\xbb\xbf"
_TEXT = re.compile(rb"\S")


class NumberRows(Sequence[tuple[int, list[str | float]]]):
    """A numeric block's rows as ``(line, cells)`` on demand, over ``values`` (R, width)."""

    def __init__(self, values: np.ndarray, lines: np.ndarray) -> None:
        self.values, self.lines = values, lines

    def __len__(self) -> int:
        return len(self.values)

    @overload
    def __getitem__(self, i: int) -> tuple[int, list[str | float]]: ...
    @overload
    def __getitem__(self, i: slice) -> list[tuple[int, list[str | float]]]: ...
    def __getitem__(
        self, i: int | slice
    ) -> tuple[int, list[str | float]] | list[tuple[int, list[str | float]]]:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        return int(self.lines[i]), self.values[i].tolist()

    def __iter__(self) -> Iterator[tuple[int, list[str | float]]]:
        return (self[k] for k in range(len(self)))


def numeric_rows(
    path: Path,
    skip_rows: int,
    header: bool,
    delimiter: str | None,
    guess: Callable[[list[str]], str],
) -> tuple[list[str] | None, NumberRows] | None:
    """The header (stripped names, when ``header``) and the rows of a plain numeric file
    (module docstring) after ``skip_rows`` lines, lines numbered as an editor does; None
    when the file is not plain. ``guess``: the delimiter of the first lines when not
    given."""
    import polars as pl

    try:
        data = path.read_bytes()
    except OSError:
        return None
    data = data.removeprefix(_BOM)
    if b'"' in data or (b"\r" in data and data.count(b"\r") != data.count(b"\r\n")):
        return None
    start = 0
    for _ in range(skip_rows):
        start = data.find(b"\n", start) + 1
        if start == 0:
            return None
    head = data[start : start + (1 << 16)].split(b"\n")[:20]
    try:
        lines = [h.decode("utf-8").removesuffix("\r") for h in head]
    except UnicodeDecodeError:
        return None
    delim = delimiter or guess(lines)
    if delim == " " or len(delim) != 1:
        return None
    names = None
    if header:
        names = [h.strip() for h in lines[0].split(delim)]
        start = data.find(b"\n", start) + 1
        if start == 0:
            return None
    if _TEXT.search(data, start) is None or data[start : start + 1] in (b"\n", b"\r"):
        return None  # no row, or a blank first row
    if data.find(b"\n\n", start) >= 0 or data.find(b"\n\r\n", start) >= 0:
        return None  # a blank line: the csv reader skips it
    width = len(names) if names is not None else len(lines[0].split(delim))
    schema = {f"c{k}": pl.Float64 for k in range(width)}
    try:
        frame = pl.read_csv(data, has_header=False, separator=delim, schema=schema,
                            quote_char=None, skip_lines=data.count(b"\n", 0, start))  # fmt: skip
    except Exception:  # noqa: BLE001 (any cell or row polars cannot read: the csv reader's)
        return None
    if frame.null_count().sum_horizontal().item():
        return None  # an empty cell or a short row: the csv reader refuses or drops it
    values = frame.to_numpy(order="c").astype(float, copy=False)
    first = skip_rows + (2 if header else 1)  # the first data row's line
    return names, NumberRows(values, np.arange(first, first + len(values), dtype=np.int64))
