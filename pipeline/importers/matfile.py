"""MATLAB ``.mat`` files (``--format mat``): the variables a map names, as blocks of rows.

A map column names a variable: ``"VAR"`` (a vector, or a matrix's first column),
``"VAR:k"`` (column k of a matrix, 1-based) or ``"S.field"`` (a field of a struct of
columns). Rows are a matrix's first dimension, as MATLAB prints it. Version 5 files
(``save``'s default) are read with ``scipy.io.loadmat``; version 7.3 files are HDF5,
read with ``h5py`` (MATLAB stores them column-major: a dataset's axes are reversed).
Each variable is one block (:mod:`pipeline.importers.grid`): the variables' rows are
joined by position and their counts checked, so joints in one matrix and the points of
each reflector in another need no ``file`` key; a stacked layout stacks the matrices that
hold points. A variable the file lacks is refused in one line naming the file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ImportFileError, one_line
from pipeline.importers.grid import Block, CellValue
from pipeline.importers.mapping import ImportMap
from pipeline.importers.rows import MeasuredRows
from pipeline.robots.description import RobotDescription

FORMAT = "mat"
_HDF5 = b"\x89HDF\r\n\x1a\n"  # the HDF5 signature: MATLAB v7.3 (at byte 512)


def variable(col: str | int) -> tuple[str | None, str | int]:
    """A map column's variable and its column there: "Q:2" -> ("Q", 2), "S.x" -> ("S",
    "x"), "t" -> ("t", 1)."""
    if isinstance(col, int):
        raise ImportFileError(
            f"column {col}: --format mat names variables, not column numbers",
            expected='"VAR", "VAR:k" (column k of a matrix) or "S.field"',
            got=str(col),
            fix='write e.g. x = "P:1" in the map',
        )
    if "." in col:
        struct, field = col.split(".", 1)
        return struct, field
    name, _, k = col.partition(":")
    if k and not (k.isdigit() and int(k) >= 1):
        raise ImportFileError(
            f"column {col!r}: the column after ':' is not a number from 1",
            expected='"VAR:k" with k = 1, 2, ...',
            fix="correct the map",
        )
    return name, int(k) if k else 1


def read_mat(paths: list[Path], imap: ImportMap, robot: RobotDescription) -> MeasuredRows:
    """Parse the ``.mat`` file(s) with their map (one after the other) into rows."""
    from pipeline.importers.table import read_table

    return read_table(paths, imap, robot, mat_blocks, variable)


def mat_blocks(path: Path, names: set[str | None]) -> dict[str | None, Block]:
    """The blocks of the variables ``names`` of ``path`` (v5 or v7.3)."""
    want = sorted(n for n in names if n)
    with path.open("rb") as f:
        head = f.read(520)
    arrays = _read_hdf5(path, want) if head[512:520] == _HDF5 else _read_v5(path, want)
    missing = [n for n in want if n not in arrays]
    if missing:
        raise ImportFileError(
            f"{path.name}: no variable {missing[0]!r}",
            expected="the variables the map names: " + ", ".join(want),
            got=", ".join(sorted(_names(path, head))) or "no variables",
            fix="correct the map's column (VAR, VAR:k or S.field), or save the variable",
        )
    return {n: _block(path, n, arrays[n]) for n in want}


def _names(path: Path, head: bytes) -> list[str]:
    """The variables of a file, for a message."""
    if head[512:520] == _HDF5:
        import h5py

        with h5py.File(path, "r") as f:
            return [k for k in f if not k.startswith("#")]
    from scipy.io import whosmat

    return [w[0] for w in whosmat(path)]


def _read_v5(path: Path, names: list[str]) -> dict[str, Any]:
    from scipy.io import loadmat

    try:
        return loadmat(path, variable_names=names, simplify_cells=True)  # type: ignore[no-any-return]
    except (ValueError, TypeError, OSError, NotImplementedError) as exc:
        raise ImportFileError(
            f"{path.name}: not a MATLAB file scipy can read",
            got=one_line(str(exc), 120),
            fix="save it with MATLAB's save (v5 or v7.3), or check --format",
        ) from None


def _read_hdf5(path: Path, names: list[str]) -> dict[str, Any]:
    import h5py

    out: dict[str, Any] = {}
    try:
        with h5py.File(path, "r") as f:
            for n in names:
                if n not in f:
                    continue
                item = f[n]
                if isinstance(item, h5py.Group):  # a struct: one dataset per field
                    out[n] = {k: np.asarray(v[()]).T for k, v in item.items()
                              if isinstance(v, h5py.Dataset)}  # fmt: skip
                else:
                    out[n] = np.asarray(item[()]).T  # MATLAB is column-major
    except OSError as exc:
        raise ImportFileError(
            f"{path.name}: not a MATLAB v7.3 (HDF5) file h5py can read",
            got=one_line(str(exc), 120),
            fix="save it again with MATLAB's save -v7.3, or check --format",
        ) from None
    return out


def _numeric(path: Path, name: str, value: Any) -> np.ndarray:
    """A variable as a 2-D float array (rows, columns); a vector is one column."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise ImportFileError(
            f"{path.name}: variable {name!r} is not numeric",
            expected="a numeric matrix or vector",
            got=f"{arr.dtype} of shape {arr.shape}",
            fix="save numbers (not text or cells) under this name",
        )
    if arr.ndim > 2:
        raise ImportFileError(
            f"{path.name}: variable {name!r} has {arr.ndim} dimensions",
            expected="a matrix (rows: poses or points) or a vector",
            got=str(arr.shape),
            fix="reshape it to rows and columns before saving",
        )
    return arr.astype(float).reshape(len(arr), -1) if arr.ndim else arr.reshape(1, 1)


def _block(path: Path, name: str, value: Any) -> Block:
    """A variable's block: a matrix's columns numbered 1, 2, ... (its header), a struct's
    fields by name (each a column vector of the same length)."""
    where = f"{path.name}: variable {name}"
    if isinstance(value, dict):
        cols = {k: _numeric(path, f"{name}.{k}", v) for k, v in value.items()}
        lengths = {k: len(v) for k, v in cols.items()}
        if len(set(lengths.values())) > 1:
            raise ImportFileError(
                f"{where}: its fields have different lengths",
                expected="one value per row in every field",
                got=", ".join(f"{k} {n}" for k, n in lengths.items()),
                fix="save fields of the same length",
            )
        header = list(cols)
        data = np.column_stack([v[:, 0] for v in cols.values()]) if cols else np.zeros((0, 0))
    else:
        data = _numeric(path, name, value)
        header = [str(k + 1) for k in range(data.shape[1])]
    rows: list[tuple[int, list[CellValue]]] = [
        (r + 1, cells) for r, cells in enumerate(data.tolist())
    ]
    return Block(where, path.name, header, rows, 1, "row")
