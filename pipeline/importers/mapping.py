"""The map file (TOML) of ``pipeline import --format table|rct``: docs/import.md.

A map is checked against ``schemas/import/map.json`` (fastjsonschema) before any of it
is used: an unknown key, a value of the wrong type (``header = "false"``,
``skip_lines = "17"``), a non-finite number or a combination the format cannot take
is refused in one line naming the key, what was expected and what arrived.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from pipeline.errors import ImportFileError, one_line
from pipeline.schemas import compiled_validator, expected_in_words, first_non_finite

SCHEMA = "import/map.json"
#: The ``[rosbag2]`` table's own schema (``--format rosbag2``).
BAG_SCHEMA = "import/rosbag2.json"
#: Sweep value of a map whose rows are all configurations of the pose set.
POSES = "poses"
_SHOWN = 80  # characters of a bad value shown in an error


@dataclass(frozen=True)
class TargetColumns:
    """One measured target: its id, its x, y, z columns (header name or 1-based number)
    and its standard deviation columns: ``sigma`` (the same for x, y, z) or ``sigma_xyz``
    (one per coordinate), in the map's length unit."""

    id: str
    x: str | int
    y: str | int
    z: str | int
    sigma: str | int | None = None
    sigma_xyz: tuple[str | int, str | int, str | int] | None = None
    file: str | None = None  # several files joined by row: the one holding these columns
    fixed: bool = False  # fixed in the world (on the base), not on the arm


@dataclass(frozen=True)
class JointColumn:
    """One joint reading: column, unit (deg | rad | mm | cm | m), unwrap 360° jumps."""

    column: str | int
    unit: str
    unwrap: bool = False
    file: str | None = None  # several files joined by row: the one holding this column


@dataclass(frozen=True)
class SweepSelect:
    """Rows forming joint ``joint``'s sweep: every other joint listed in ``held`` reads its
    value there (deg / cm, within the tolerance)."""

    joint: int
    held: dict[int, float]


@dataclass(frozen=True)
class OrientationColumns:
    """Euler angles of the tool target's frame: columns, unit, scipy sequence."""

    columns: tuple[str | int, str | int, str | int]
    unit: str
    convention: str
    sigma_deg: float | None = None  # stated σ per rotation-vector component


@dataclass(frozen=True)
class CheckSplit:
    """A pose set's rows imported as sweep ``check``: a seeded random ``fraction``, the
    rows whose ``column`` is true, the rows of ``files`` (names or globs), or the data
    rows of ``ranges`` (1-based, both ends included, over the files in order)."""

    fraction: float | None = None
    seed: int | None = None
    column: str | int | None = None
    files: tuple[str, ...] = ()
    ranges: tuple[tuple[int, int], ...] = ()


@dataclass(frozen=True)
class ImportMap:
    """What the columns of a table mean, and how rows form sweeps or a pose set
    (docs/import.md)."""

    path: Path | None = None
    delimiter: str | None = None
    decimal: str = "."
    skip_rows: int = 0
    skip_lines: tuple[int, ...] = ()
    header: bool = True
    length_unit: str = "mm"
    targets: tuple[TargetColumns, ...] = ()
    joints: tuple[JointColumn, ...] = ()
    sweep_column: str | int | None = None  # a column, "infer", or None (select)
    select: tuple[SweepSelect, ...] = ()
    tolerance: tuple[float, ...] | float | None = None  # deg / cm; None: encoder resolution
    duplicate: tuple[float, ...] | float | None = None  # deg / cm; None: encoder resolution
    home: tuple[float, ...] | None = None  # deg / cm
    poses: bool = False  # every row a configuration of the pose set
    tool_target: str | None = None  # None: the first target
    tool_offset: tuple[float, float, float] | None = None  # length_unit
    sigma: float | None = None  # length_unit, every coordinate of every point
    payload_kg: float | None = None  # the payload on the flange at every row
    payload_column: str | int | None = None  # or a column of it (kg)
    orientation: OrientationColumns | None = None
    check: CheckSplit | None = None
    points_per_pose: int | None = None  # stacked: this many rows per pose
    pose_column: str | int | None = None  # stacked: rows sharing its value are one pose
    sigma_floor: float | None = None  # length_unit; None: the tracker's resolution
    fixed_block: int = 1  # fixed targets: poses per registration
    fixed_correction: str = "auto"  # fixed targets: auto (when they move) | always | never
    tool_point_q: tuple[float, ...] | None = None  # validate --tool-point ID: where located
    strict: bool = False  # --strict, not a map key: refuse a missing value, do not drop
    rosbag2: dict[str, Any] | None = None  # the [rosbag2] table, checked (importers.rosbag2)

    @property
    def joined(self) -> bool:
        """Several files joined by row (a ``file`` key in [[targets]] or [[joints]])."""
        return any(t.file for t in self.targets) or any(j.file for j in self.joints)

    @property
    def name(self) -> str:
        """The map's file name for messages ("map" without a file)."""
        return self.path.name if self.path else "map"

    @property
    def sigma_cm(self) -> float | None:
        """The stated ``sigma`` in cm (it is in ``length_unit``), None when not stated."""
        from pipeline.importers.rows import LENGTH_CM, unit_factor

        if self.sigma is None:
            return None
        unit = unit_factor(self.length_unit, LENGTH_CM, "length", f"{self.name}: length_unit")
        return self.sigma * unit

    def only_sigma(self, fmt: str) -> None:
        """Refuse a map that says more than a σ (``sigma``, ``length_unit``) for ``fmt``,
        a format whose file states everything else (sscanss2)."""
        plain = replace(self, path=None, sigma=None, length_unit=ImportMap.length_unit,
                        strict=False)  # fmt: skip
        if plain != ImportMap():
            raise ImportFileError(
                f"{self.name}: --format {fmt} reads only sigma and length_unit from a map",
                expected="a map of: sigma = 0.01 (and length_unit, default mm)",
                got="columns, sweeps or other keys",
                fix=f"drop the other keys (the {fmt} file states its columns and sweeps)",
            )


def _refuse(src: str, key: str, what: str, expected: str, got: Any) -> ImportFileError:
    return ImportFileError(
        f"{src}: {key}: {what}",
        expected=expected,
        got=one_line(repr(got), _SHOWN),
        fix="correct the map (docs/import.md, schemas/import/map.json)",
    )


def _finite(src: str, data: Any) -> None:
    """Refuse ``nan`` and ``inf`` (TOML has them, the map's numbers must be finite)."""
    bad = first_non_finite(data)
    if bad is not None:
        raise _refuse(src, bad[0], "is not a finite number", "a finite number", bad[1])


def check_map(src: str, data: Any) -> dict[str, Any]:
    """``data`` (a parsed map) checked against the map schema; ``src`` names it in errors."""
    from fastjsonschema import JsonSchemaValueException

    _finite(src, data)
    for schema, part, prefix in ((SCHEMA, data, ""), (BAG_SCHEMA, None, "rosbag2")):
        if prefix:
            if not isinstance(data, dict) or "rosbag2" not in data:
                continue
            part = data["rosbag2"]
        try:
            compiled_validator(schema)(part)
        except JsonSchemaValueException as exc:
            name = str(exc.name)
            key = ".".join(k for k in (prefix, name.removeprefix("data").removeprefix(".")) if k)
            what = one_line(exc.message.removeprefix(name).strip(), _SHOWN)
            expected = expected_in_words(str(exc.rule), exc.definition or {})
            raise _refuse(src, key or "map", what, expected, exc.value) from None
    _check_combinations(src, data)
    return data  # type: ignore[no-any-return]


def _check_combinations(src: str, data: dict[str, Any]) -> None:
    """What one key's schema cannot say: keys that exclude or need each other."""
    poses = data.get("sweep") == POSES
    if poses and "sweeps" in data:
        raise _refuse(src, "sweeps", 'is not read with sweep = "poses"',
                      'either sweep = "poses" or a [sweeps] table', data["sweeps"])  # fmt: skip
    for key in ("check", "tool_offset"):
        if key in data and not poses:
            raise _refuse(src, key, 'applies to a pose set only', 'sweep = "poses" in the map',
                          data[key])  # fmt: skip
    for k, j in enumerate(data.get("joints", [])):
        if poses and j.get("unwrap"):
            raise _refuse(src, f"joints[{k}].unwrap", "has no sweep to unwrap in a pose set",
                          'unwrap = false with sweep = "poses"', True)  # fmt: skip
    targets = data.get("targets", [])
    for k, t in enumerate(targets):
        axes = [a for a in ("sigma_x", "sigma_y", "sigma_z") if a in t]
        if axes and len(axes) != 3:
            raise _refuse(src, f"targets[{k}]", "names some but not all sigma_x/y/z columns",
                          "all three of sigma_x, sigma_y, sigma_z, or none", axes)  # fmt: skip
        if axes and "sigma" in t:
            raise _refuse(src, f"targets[{k}]", "has both sigma and sigma_x/y/z",
                          "one σ column, or one per axis", sorted(t))  # fmt: skip
        if (axes or "sigma" in t) and "sigma" in data:
            raise _refuse(src, "sigma", f"is stated and targets[{k}] has σ columns too",
                          "one stated σ for the file, or σ columns", data["sigma"])  # fmt: skip
    check = data.get("check")
    if check is not None:
        ways = [k for k in ("fraction", "column", "files", "rows") if k in check]
        if len(ways) != 1 or ("fraction" in check) != ("seed" in check):
            raise _refuse(src, "check", "names the held-out rows in none or several ways",
                          "fraction and seed, column, files or rows", sorted(check))  # fmt: skip
        for k, (a, b) in enumerate(check.get("rows", [])):
            if a > b:
                raise _refuse(src, f"check.rows[{k}]", "ends before it starts",
                              "[first, last] with first <= last", [a, b])  # fmt: skip
    if "points_per_pose" in data and "pose_column" in data:
        raise _refuse(src, "pose_column", "is given and points_per_pose too",
                      "one way of stacking rows", data["pose_column"])  # fmt: skip
    if "payload_kg" in data and "payload_column" in data:
        raise _refuse(
            src, "payload_kg", "is stated and payload_column is given too",
            "one payload for the file, or a column of it", data["payload_kg"],
        )  # fmt: skip
    fixed = [str(t.get("id", f"t{k + 1}")) for k, t in enumerate(targets) if t.get("fixed")]
    if fixed and not poses:
        raise _refuse(src, "targets", "has fixed targets outside a pose set",
                      'sweep = "poses" with fixed = true', fixed)  # fmt: skip
    if fixed and len(fixed) == len(targets):
        raise _refuse(src, "targets", "are all fixed in the world: no point of the arm",
                      "at least one [[targets]] on the arm (fixed = false)", fixed)  # fmt: skip
    for key in ("fixed_block", "fixed_correction"):  # would do nothing: said, not ignored
        if key in data and not fixed:
            raise _refuse(
                src,
                key,
                "is given, but no [[targets]] is fixed on the base",
                f"fixed = true on the base's reflectors, or no {key}",
                data[key],
            )
    if data.get("tool_target") in fixed:
        raise _refuse(src, "tool_target", "is a fixed target, not a point of the arm",
                      "a [[targets]] id without fixed = true", data["tool_target"])  # fmt: skip
    ids = [str(t.get("id", f"t{k + 1}")) for k, t in enumerate(targets)]
    if len(set(ids)) != len(ids):
        raise _refuse(src, "targets", "names a target id twice", "distinct ids", ids)
    ids += [str(t["id"]) for t in data.get("rosbag2", {}).get("targets", [])]
    if "tool_target" in data and data["tool_target"] not in ids:
        raise _refuse(src, "tool_target", "is not the id of a [[targets]] table",
                      " | ".join(ids) or "a [[targets]] table", data["tool_target"])  # fmt: skip


def load_map(path: Path) -> ImportMap:
    """Read and check a map file; a malformed one is refused naming the key."""
    src = path.name
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportFileError(
            f"cannot read map {path}", got=one_line(str(exc)), fix="check --map"
        ) from exc
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise ImportFileError(
            f"{src}: not valid TOML", got=one_line(str(exc), _SHOWN), fix="see docs/import.md"
        ) from exc
    return map_from_dict(check_map(src, data), path)


def map_from_dict(data: dict[str, Any], path: Path | None = None) -> ImportMap:
    """The :class:`ImportMap` of a map checked by :func:`check_map`."""
    targets = tuple(
        TargetColumns(
            str(t.get("id", f"t{k + 1}")),
            t["x"],
            t["y"],
            t["z"],
            t.get("sigma"),
            (t["sigma_x"], t["sigma_y"], t["sigma_z"]) if "sigma_x" in t else None,
            t.get("file"),
            bool(t.get("fixed", False)),
        )
        for k, t in enumerate(data.get("targets", []))
    )
    joints = tuple(
        JointColumn(j["column"], j.get("unit", "deg"), j.get("unwrap", False), j.get("file"))
        for j in data.get("joints", [])
    )
    sw = data.get("sweeps", {})
    select = tuple(
        SweepSelect(s["joint"], {int(j): float(v) for j, v in s.get("held", {}).items()})
        for s in sw.get("select", [])
    )
    tol, dup = sw.get("tolerance"), sw.get("duplicate")
    orient = data.get("orientation")
    check = data.get("check")
    return ImportMap(
        path=path,
        delimiter=data.get("delimiter"),
        decimal=data.get("decimal", "."),
        skip_rows=int(data.get("skip_rows", 0)),
        skip_lines=tuple(int(v) for v in data.get("skip_lines", [])),
        header=data.get("header", True),
        length_unit=data.get("length_unit", "mm"),
        targets=targets,
        joints=joints,
        sweep_column=sw.get("column"),
        select=select,
        tolerance=tuple(map(float, tol)) if isinstance(tol, list) else tol,
        duplicate=tuple(map(float, dup)) if isinstance(dup, list) else dup,
        home=None if "home" not in sw else tuple(float(v) for v in sw["home"]),
        poses=data.get("sweep") == POSES,
        tool_target=data.get("tool_target"),
        tool_offset=None if "tool_offset" not in data else tuple(data["tool_offset"]),  # type: ignore[arg-type]
        sigma=data.get("sigma"),
        payload_kg=data.get("payload_kg"),
        payload_column=data.get("payload_column"),
        orientation=None
        if orient is None
        else OrientationColumns(
            (orient["rx"], orient["ry"], orient["rz"]),
            orient.get("unit", "deg"),
            orient["convention"],
            orient.get("sigma_deg"),
        ),
        check=None if check is None else _check_split(check),
        points_per_pose=data.get("points_per_pose"),
        pose_column=data.get("pose_column"),
        sigma_floor=data.get("sigma_floor"),
        fixed_block=int(data.get("fixed_block", 1)),
        fixed_correction=data.get("fixed_correction", "auto"),
        tool_point_q=None
        if "tool_point_q" not in data
        else tuple(float(v) for v in data["tool_point_q"]),
        rosbag2=data.get("rosbag2"),
    )


def _check_split(check: dict[str, Any]) -> CheckSplit:
    return CheckSplit(
        None if "fraction" not in check else float(check["fraction"]),
        None if "seed" not in check else int(check["seed"]),
        check.get("column"),
        tuple(check.get("files", ())),
        tuple((int(a), int(b)) for a, b in check.get("rows", ())),
    )
