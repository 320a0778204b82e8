"""The map file (TOML) of ``pipeline import --format table|rct``: docs/import.md."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.errors import ImportFileError


@dataclass(frozen=True)
class TargetColumns:
    """One measured target: its id and its x, y, z columns (header name or 1-based number)."""

    id: str
    x: str | int
    y: str | int
    z: str | int


@dataclass(frozen=True)
class JointColumn:
    """One joint reading: column, unit (deg | rad | mm | cm | m), unwrap 360° jumps."""

    column: str | int
    unit: str
    unwrap: bool = False


@dataclass(frozen=True)
class SweepSelect:
    """Rows forming joint ``joint``'s sweep: every other joint listed in ``held`` reads its
    value there (deg / cm, within the tolerance)."""

    joint: int
    held: dict[int, float]


@dataclass(frozen=True)
class ImportMap:
    """What the columns of a table mean, and how rows form sweeps (docs/import.md)."""

    path: Path | None = None
    delimiter: str | None = None
    skip_rows: int = 0
    skip_lines: tuple[int, ...] = ()
    header: bool = True
    length_unit: str = "mm"
    targets: tuple[TargetColumns, ...] = ()
    joints: tuple[JointColumn, ...] = ()
    sweep_column: str | int | None = None  # a column, "infer", or None (select)
    select: tuple[SweepSelect, ...] = ()
    tolerance: tuple[float, ...] | float | None = None  # deg / cm; None: encoder resolution
    home: tuple[float, ...] | None = None  # deg / cm


_TOP = ("format", "delimiter", "skip_rows", "skip_lines", "header", "length_unit", "targets",
        "joints", "sweeps")  # fmt: skip
_SWEEPS = ("column", "select", "tolerance", "home")


def _fail(src: str, where: str, what: str, expected: str, got: Any) -> ImportFileError:
    return ImportFileError(
        f"{src}: {where}: {what}", expected=expected, got=repr(got), fix="see docs/import.md"
    )


def _check_keys(src: str, where: str, table: Any, allowed: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise _fail(src, where, "is not a table", "a TOML table", table)
    for key in table:
        if key not in allowed:
            raise _fail(src, where, f"unknown field '{key}'", ", ".join(allowed), key)
    return table


def _column(src: str, where: str, v: Any) -> str | int:
    if isinstance(v, str) or (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
        return v
    raise _fail(src, where, "is not a column", "a header name or a 1-based column number", v)


def _numbers(src: str, where: str, v: Any) -> tuple[float, ...]:
    if isinstance(v, list) and all(
        isinstance(x, int | float) and not isinstance(x, bool) for x in v
    ):
        return tuple(float(x) for x in v)
    raise _fail(src, where, "is not a list of numbers", "[number, ...]", v)


def load_map(path: Path) -> ImportMap:
    """Read and check a map file; a malformed one is refused naming the field."""
    src = path.name
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ImportFileError(f"cannot read map {path}", got=str(exc), fix="check --map") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ImportFileError(
            f"{src}: not valid TOML", got=str(exc), fix="see docs/import.md"
        ) from exc
    _check_keys(src, "map", data, _TOP)
    targets = tuple(
        TargetColumns(
            str(t.get("id", f"t{k + 1}")),
            *(_column(src, f"targets[{k}].{c}", t.get(c)) for c in "xyz"),
        )
        for k, t in enumerate(data.get("targets", []))
        if _check_keys(src, f"targets[{k}]", t, ("id", "x", "y", "z"))
    )
    joints = tuple(
        JointColumn(
            _column(src, f"joints[{k}].column", j.get("column")),
            str(j.get("unit", "deg")),
            bool(j.get("unwrap", False)),
        )
        for k, j in enumerate(data.get("joints", []))
        if _check_keys(src, f"joints[{k}]", j, ("column", "unit", "unwrap"))
    )
    sw = _check_keys(src, "sweeps", data.get("sweeps", {}), _SWEEPS)
    select = []
    for k, s in enumerate(sw.get("select", [])):
        _check_keys(src, f"sweeps.select[{k}]", s, ("joint", "held"))
        held = _check_keys(
            src, f"sweeps.select[{k}].held", s.get("held", {}), tuple(s.get("held", {}))
        )
        try:
            select.append(SweepSelect(int(s["joint"]), {int(j): float(v) for j, v in held.items()}))
        except (KeyError, ValueError, TypeError):
            raise _fail(src, f"sweeps.select[{k}]", "is malformed",
                        "joint = N and held = { \"J\" = reading, ... }", s) from None  # fmt: skip
    tol = sw.get("tolerance")
    if tol is not None and not isinstance(tol, int | float):
        tol = _numbers(src, "sweeps.tolerance", tol)
    column = sw.get("column")
    return ImportMap(
        path=path,
        delimiter=data.get("delimiter"),
        skip_rows=int(data.get("skip_rows", 0)),
        skip_lines=tuple(int(v) for v in data.get("skip_lines", [])),
        header=bool(data.get("header", True)),
        length_unit=str(data.get("length_unit", "mm")),
        targets=targets,
        joints=joints,
        sweep_column=None if column is None else _column(src, "sweeps.column", column),
        select=tuple(select),
        tolerance=tol if tol is None or isinstance(tol, tuple) else float(tol),
        home=None if "home" not in sw else _numbers(src, "sweeps.home", sw["home"]),
    )
