"""``pipeline import``: foreign measurement files -> point-session recordings.

One module per format parses a file into :class:`~pipeline.importers.rows.MeasuredRows`
(armsig's units, a sweep per row); :mod:`~pipeline.importers.session` turns checked
rows into the recording's messages and :mod:`~pipeline.importers.write` writes them.
Formats and the map file: docs/import.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pipeline.errors import ImportFileError, os_errors_refused
from pipeline.importers.mapping import ImportMap, load_map
from pipeline.importers.memory import check_fits
from pipeline.importers.rows import LENGTH_CM, MeasuredRows, checked_rows, concat_rows
from pipeline.importers.session import ToolChoice, session_messages, tool_rows
from pipeline.importers.sweeps import (
    Tolerances,
    home_readings,
    pose_set,
    select_sweeps,
    tolerances,
)
from pipeline.importers.write import source_metadata, write_imported
from pipeline.robots.description import RobotDescription, load_description

FORMATS = ("sscanss2", "table", "rct", "mat", "rosbag2", "images")  # images: a camera session
#: What to try after an OSError of import or validate (:func:`~pipeline.errors.os_errors_refused`).
OS_FIX = "check the path (a name of at most 255 bytes), its permissions and the free space"


@dataclass(frozen=True)
class Imported:
    """A converted file: its checked rows, the tool choice, where it was written."""

    rows: MeasuredRows
    tool: ToolChoice
    robot: RobotDescription
    recording: Path | None


def _tolerances(fmt: str, imap: ImportMap, robot: RobotDescription) -> Tolerances:
    """How far a held joint may be from its sweep's value, and how close two stops of a
    sweep may be (deg / cm)."""
    if fmt == "sscanss2":
        half = robot.encoder_resolution / 2  # the file states each configuration exactly
        return Tolerances(half, half)
    return tolerances(imap, robot)


def expand_paths(specs: list[str | Path], folders: bool = False) -> list[Path]:
    """The files of ``specs`` in order: each a path, or a glob (its matches sorted by
    name); a glob that matches nothing, or a file given twice, is refused in one line.
    ``folders``: a folder is taken too (a ROS 2 bag)."""
    import glob

    out: list[Path] = []
    for spec in specs:
        text = str(spec)
        hits = sorted(glob.glob(text)) if glob.has_magic(text) else [text]
        if not hits:
            raise ImportFileError(
                f"{text}: no file matches", expected="a path, or a glob that matches a file",
                fix="check the pattern (quote it so that armsig, not the shell, expands it)",
            )  # fmt: skip
        out += [Path(h) for h in hits]
    seen = [p.resolve() for p in out]
    twice = [p for k, p in enumerate(out) if seen[k] in seen[:k]]
    if twice:
        raise ImportFileError(
            f"{twice[0]}: given twice", expected="each file once",
            fix="drop the repeated path or the overlapping glob",
        )  # fmt: skip
    for p in out:
        if not (p.is_file() or (folders and p.is_dir())):
            raise ImportFileError(f"{p}: no such file", fix="check the path")
    return out


def parse_foreign(
    paths: Path | list[Path], fmt: str, robot: RobotDescription, imap: ImportMap
) -> tuple[MeasuredRows, np.ndarray]:
    """Parse foreign file(s) (not yet checked for a session), one after the other; their
    rows and the home readings. robot_cal_tools' YAML without a sweep selection: every
    row a ``check``."""
    files = [paths] if isinstance(paths, Path) else list(paths)
    if fmt not in FORMATS:
        raise ImportFileError(
            f"unknown import format {fmt!r}", expected=" | ".join(FORMATS), fix="--format sscanss2"
        )
    if fmt == "rosbag2":
        if len(files) != 1:
            raise ImportFileError(
                f"--format rosbag2 takes one bag, got {len(files)}",
                fix="import each bag as its own session (or merge them: ros2 bag convert)",
            )
        return _with_home(_rosbag2(files[0], robot, imap), imap, robot)
    for path in files:
        if not path.is_file():
            raise ImportFileError(f"{path}: no such file", fix="check the path")
    if fmt == "images":
        raise ImportFileError(
            f"{files[0].name}: --format images holds camera images, not measured points",
            expected="sscanss2 | table | rct | mat | rosbag2",
            fix="`pipeline import FILE NAME --format images` makes a camera session of it",
        )
    if fmt == "sscanss2":
        from pipeline.importers.sscanss2 import read_sscanss2

        imap.only_sigma(fmt)
        parsed = [read_sscanss2(p, robot) for p in files]
        _same_home(parsed, files)
        rows = concat_rows([r for r, _ in parsed])
        return rows.with_sigma(imap.sigma_cm), parsed[0][1]
    if fmt in ("table", "mat"):
        if imap.path is None:
            raise ImportFileError(
                f"{files[0].name}: --format {fmt} needs --map MAP.toml",
                fix="write a map of the columns (docs/import.md)",
            )
        if fmt == "table":
            from pipeline.importers.table import read_table

            rows = read_table(files, imap, robot)
        else:
            from pipeline.importers.matfile import read_mat

            rows = read_mat(files, imap, robot)
    else:
        from pipeline.importers.rct import read_rct

        rows = concat_rows([read_rct(p, robot) for p in files]).with_sigma(imap.sigma_cm)
        if imap.poses:
            rows = pose_set(rows, imap)
        elif imap.select:
            rows = select_sweeps(rows, imap, robot, _tolerances(fmt, imap, robot).held)
    return _with_home(rows, imap, robot)


def _with_home(
    rows: MeasuredRows, imap: ImportMap, robot: RobotDescription
) -> tuple[MeasuredRows, np.ndarray]:
    """The rows and their home readings (zeros when no row is a joint's sweep)."""
    if not (rows.sweep > 0).any():
        return rows, np.zeros(robot.n_joints)
    return rows, home_readings(rows, imap, robot)


def _rosbag2(path: Path, robot: RobotDescription, imap: ImportMap) -> MeasuredRows:
    """A ROS 2 bag's stops (:mod:`pipeline.importers.rosbag2`) formed into sweeps or a
    pose set as a table's rows are (:func:`pipeline.importers.table.assigned`); the settle
    rule's counts in the rows' notes."""
    from pipeline.importers.rosbag2 import read_rosbag2
    from pipeline.importers.table import assigned

    bag = read_rosbag2(path, imap, robot)
    rows = replace(bag.rows.with_sigma(imap.sigma_cm), notes=(bag.note,))
    if not rows.where:
        raise ImportFileError(
            f"{path.name}: no stop with a point: {bag.note}",
            expected="the arm still for settle_s with points measured then",
            fix="check rosbag2.still (deg / cm) and settle_s against the bag's joint states",
        )
    return assigned(rows, imap, robot, sweep_column=False)


def _same_home(parsed: list[tuple[MeasuredRows, np.ndarray]], files: list[Path]) -> None:
    """SScanSS-2 files of one data set state the same home; refused in one line if not."""
    for (_, home), path in zip(parsed[1:], files[1:], strict=True):
        if not np.array_equal(home, parsed[0][1]):
            raise ImportFileError(
                f"{path.name}: home {home.tolist()} differs from {files[0].name}'s "
                f"{parsed[0][1].tolist()}",
                expected="one home per joint over the files of one data set",
                fix="import the files as separate sessions",
            )


def read_foreign(
    paths: Path | list[Path], fmt: str, robot: RobotDescription, imap: ImportMap
) -> tuple[MeasuredRows, ToolChoice]:
    """Parse and check foreign file(s) for a session; the rows and the tool measurement."""
    files = [paths] if isinstance(paths, Path) else list(paths)
    if fmt == "rct" and not imap.select and not imap.poses:
        raise ImportFileError(
            f'{files[0].name}: --format rct needs [[sweeps.select]] or sweep = "poses" in --map',
            expected="which rows form each joint's sweep (docs/import.md)",
            fix='e.g. joint = 2 with held = { "1" = 0.0 }',
        )
    rows, home = parse_foreign(files, fmt, robot, imap)
    check_fits(rows.name, len(rows.where))  # no fixed limit: what memory takes
    tol = _tolerances(fmt, imap, robot)
    rows = checked_rows(rows, robot, tol)
    return rows, tool_rows(rows, home, robot, tol.held)


def import_file(
    path: str | Path | list[str | Path],
    fmt: str,
    robot_path: str | Path,
    session_dir: str | Path,
    map_path: str | Path | None = None,
    force: bool = False,
    strict: bool = False,
    robot_id: str | None = None,
) -> Imported:
    """Convert the file(s) ``path`` (paths or globs, in order; a ROS 2 bag folder) into
    ``session_dir/recording.mcap`` (a point session). A row with a missing measured value
    is dropped and said in ``rows.notes``; ``strict``: refused instead. ``robot_id``: the
    measured arm's own id (serial), recorded for ``pipeline fleet``."""
    specs = path if isinstance(path, list) else [path]
    if robot_id is not None:
        from pipeline.contract.channels import check_robot_id

        check_robot_id(robot_id)
    with os_errors_refused(Path(session_dir) / "recording.mcap", OS_FIX):
        files = expand_paths(specs, folders=fmt == "rosbag2")
        robot = load_description(robot_path)
        mp = None if map_path is None else Path(map_path)
        imap = replace(load_map(mp) if mp is not None else ImportMap(), strict=strict)
        rows, tool = read_foreign(files, fmt, robot, imap)
        local = None
        if imap.tool_offset is not None:
            local = np.array(imap.tool_offset) * LENGTH_CM[imap.length_unit]
        names = f"file {files[0].name}"
        if len(files) > 1:
            names = f"files {files[0].name} to {files[-1].name} ({len(files)})"
        note = f"{fmt} {names} (imported)"
        messages = session_messages(rows, robot, tool, note, local, robot_id)
        if fmt == "rosbag2":  # a bag folder: its data is its .mcap file
            from pipeline.importers.rosbag2 import bag_file

            files = [bag_file(files[0])]
        recording = write_imported(
            Path(session_dir), messages, source_metadata(files, fmt, mp), force
        )
    return Imported(rows, tool, robot, recording)


__all__ = [
    "FORMATS",
    "OS_FIX",
    "Imported",
    "expand_paths",
    "import_file",
    "parse_foreign",
    "read_foreign",
]
