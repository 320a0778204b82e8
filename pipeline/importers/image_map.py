"""The map file (TOML) and table of ``pipeline import TABLE NAME --format images --map
MAP.toml`` (``schemas/import/images_map.json``; docs/import.md, "Image sets").

The map names the image folder, the target file, the lens and the set-up, and the
columns of the table (a delimited text file with a header, one row per image) that hold
each image's file name and either its joint readings (``[[joints]]``: column and unit per
joint of ``--robot``, as for tracker tables) or its flange pose (``[flange]``: x, y, z in
``length_unit`` and the quaternion qx, qy, qz, qw). A map naming a column the table does
not have, a missing or non-numeric cell, or a quaternion that is not a rotation is
refused in one line naming the table, the line and the column.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, ImportFileError, one_line
from pipeline.importers.rows import LENGTH_CM, readings_in_boundary_units
from pipeline.importers.sscanss2 import read_text
from pipeline.importers.table import cell_reader
from pipeline.robots.description import RobotDescription
from pipeline.schemas import compiled_validator, expected_in_words, first_non_finite
from pipeline.sensor.target import Target, target_from_toml

SCHEMA = "import/images_map.json"
IMAGES_FIX = "correct the file (docs/import.md, Image sets)"
_FIX = "correct the map (docs/import.md, Image sets; schemas/import/images_map.json)"
_POSE = ("x", "y", "z", "qx", "qy", "qz", "qw")
QUAT_NORM_TOL = 1e-3  # as robot_cal_tools' files (importers/rct.py): a text file's rounding


@dataclass(frozen=True)
class ImageMap:
    """A checked image-set map; paths resolved against the map's folder."""

    path: Path
    images: Path
    image_column: str
    delimiter: str
    target: Target
    setup: str
    camera: dict[str, float]
    joints: tuple[tuple[str, str], ...]  # (column, unit) per joint; () with a flange
    flange: dict[str, str] | None  # pose key -> column, and length_unit


@dataclass(frozen=True)
class ImageRows:
    """One row per image: its file (relative to the image folder), its table line, and
    its joint readings (N, n, deg / cm) or flange poses in the base (N, 4, 4, cm)."""

    files: tuple[str, ...]
    lines: tuple[int, ...]
    readings: np.ndarray | None
    flange_in_base: np.ndarray | None


def checked_document(src: str, data: Any, schema: str, fix: str = IMAGES_FIX) -> Any:
    """``data`` (a parsed file ``src``) checked against ``schemas/<schema>``: the first
    non-finite number or schema violation refused in one line naming its key."""
    from fastjsonschema import JsonSchemaValueException

    bad = first_non_finite(data)
    if bad is not None:
        raise ImportFileError(f"{src}: {bad[0]}: is not a finite number", got=repr(bad[1]),
                              fix=fix)  # fmt: skip
    try:
        compiled_validator(schema)(data)
    except JsonSchemaValueException as exc:
        name = str(exc.name)
        key = name.removeprefix("data").removeprefix(".") or "file"
        raise ImportFileError(
            f"{src}: {key}: {one_line(exc.message.removeprefix(name).strip(), 80)}",
            expected=expected_in_words(str(exc.rule), exc.definition or {}),
            got=one_line(repr(exc.value), 80),
            fix=fix,
        ) from None
    return data


def load_image_map(path: Path) -> ImageMap:
    """Read and check an image-set map (module docstring)."""
    src = path.name
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportFileError(f"cannot read map {path}", got=one_line(str(exc)),
                              fix="check --map") from None  # fmt: skip
    except tomllib.TOMLDecodeError as exc:
        raise ImportFileError(f"{src}: not valid TOML", got=one_line(str(exc), 80),
                              fix=_FIX) from None  # fmt: skip
    checked_document(src, data, SCHEMA, _FIX)
    if ("joints" in data) == ("flange" in data):
        raise ImportFileError(f"{src}: joints and flange: give exactly one",
                              expected="[[joints]] (the arm is calibrated) or [flange] (it is not)",
                              got="both" if "joints" in data else "neither", fix=_FIX)  # fmt: skip
    root = path.parent
    target_file = root / data["target"]
    try:
        target = target_from_toml(read_text(target_file), data["target"])
    except ArmsigError as exc:
        raise ImportFileError(f"{src}: target: {exc}") from None
    joints = tuple((j["column"], j.get("unit", "deg")) for j in data.get("joints", []))
    flange = dict(data["flange"]) if "flange" in data else None
    return ImageMap(path, root / data["images"], data["image_column"],
                    data.get("delimiter", ","), target, data["setup"], dict(data["camera"]),
                    joints, flange)  # fmt: skip


def read_image_table(path: Path, imap: ImageMap, robot: RobotDescription | None) -> ImageRows:
    """The table's rows: image files and joint readings (``robot`` given) or flange poses."""
    from pipeline.importers.grid import delimited_block, joined

    src = path.name
    if not path.is_file():
        raise ImportFileError(f"{path}: no such file", fix="check the path")
    block = delimited_block(path, 0, (), True, imap.delimiter, ".")
    if not block.rows:
        raise ImportFileError(f"{src}: no rows", expected="a header and one row per image",
                              fix="check the file")  # fmt: skip
    grid = joined([block])
    cell = cell_reader(grid, ".")
    k_image = grid.index(0, imap.image_column, "image_column")
    files = tuple(str(f[k_image]).strip() if k_image < len(f) else "" for f in grid.rows)
    lines = tuple(int(n) for n in grid.lines[:, 0])
    for name, line in zip(files, lines, strict=True):
        if not name:
            raise ImportFileError(
                f"{src}: line {line}: no image in column {imap.image_column!r}",
                fix="name the image or delete the row",
            )
    if imap.flange is not None:
        return ImageRows(files, lines, None, _flange(grid, imap, cell))
    if robot is None:
        raise ImportFileError(f"{imap.path.name}: [[joints]] needs --robot",
                              fix="--robot ROBOT.toml, the description of the arm")  # fmt: skip
    if len(imap.joints) != robot.n_joints:
        raise ImportFileError(f"{imap.path.name}: {len(imap.joints)} [[joints]] for robot "
                              f"{robot.name}", expected=f"{robot.n_joints}, one per joint",
                              fix=_FIX)  # fmt: skip
    cols = [grid.index(0, c, f"joint {j + 1}") for j, (c, _) in enumerate(imap.joints)]
    values = np.array([[_number(grid, cell, r, k, f"joint {j + 1}") for j, k in enumerate(cols)]
                       for r in range(len(grid.rows))])  # fmt: skip
    units = [u for _, u in imap.joints]
    readings = readings_in_boundary_units(values, units, robot, f"{imap.path.name}: joints")
    return ImageRows(files, lines, readings, None)


def _number(grid: Any, cell: Any, r: int, k: int, what: str) -> float:
    """Row ``r``'s number in column ``k``; a missing one is refused naming its place."""
    value = float(cell(grid.rows[r], k, r, what))
    if not np.isfinite(value):
        raise ImportFileError(f"{grid.place(k, r)}: {what} is missing",
                              fix="fill the cell or delete the row")  # fmt: skip
    return value


def _flange(grid: Any, imap: ImageMap, cell: Any) -> np.ndarray:
    """The flange poses (N, 4, 4, cm) of the table's pose columns."""
    from scipy.spatial.transform import Rotation

    assert imap.flange is not None
    src = grid.blocks[0].name
    cols = [grid.index(0, imap.flange[k], k) for k in _POSE]
    pose = np.array([[_number(grid, cell, r, c, k) for c, k in zip(cols, _POSE, strict=True)]
                     for r in range(len(grid.rows))])  # fmt: skip
    norm = np.linalg.norm(pose[:, 3:], axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
    if len(bad):
        line = grid.lines[bad[0], 0]
        raise ImportFileError(f"{src}: line {line}: the quaternion is not a rotation",
                              expected=f"norm 1 ± {QUAT_NORM_TOL:g}", got=f"{norm[bad[0]]:g}",
                              fix="correct or delete the row")  # fmt: skip
    T = np.tile(np.eye(4), (len(pose), 1, 1))
    T[:, :3, :3] = Rotation.from_quat(pose[:, 3:] / norm[:, None]).as_matrix()
    T[:, :3, 3] = pose[:, :3] * LENGTH_CM[imap.flange.get("length_unit", "m")]
    return T
