"""Which rows form which joint's sweep (a sweep column, ``infer``, or a selection), or
the pose set (every row, a seeded fraction of them validation configurations).

A file holds the controller's readings; which joint moves and which holds is a matter of
joint values, the readings through the robot's coupling when it has one
(:meth:`~pipeline.robots.description.RobotDescription.joints_from_readings`): a coupled
controller's elbow reading follows the shoulder while the elbow itself holds."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.mapping import ImportMap
from pipeline.importers.rows import MeasuredRows, Tolerances, concat_rows
from pipeline.robots.description import RobotDescription
from pipeline.stages.recording import CHECK_SWEEP, POSES_SWEEP


def _per_joint(
    value: tuple[float, ...] | float | None, key: str, imap: ImportMap, robot: RobotDescription
) -> np.ndarray:
    """A map's ``sweeps.<key>`` per joint (one number or one per joint); None: the encoder
    resolution."""
    if value is None:
        return robot.encoder_resolution
    v = np.asarray(value, float)
    if v.ndim and len(v) != robot.n_joints:
        raise ImportFileError(
            f"{imap.name}: sweeps.{key} has {len(v)} values",
            expected=f"one number, or {robot.n_joints} (one per joint of {robot.name})",
            fix="list one value per joint, or give one number for all",
        )
    return np.broadcast_to(v, (robot.n_joints,)).copy()


def tolerances(imap: ImportMap, robot: RobotDescription) -> Tolerances:
    """The map's ``tolerance`` (held joints) and ``duplicate`` (stops of a sweep), each
    the encoder resolution when the map has none."""
    return Tolerances(
        _per_joint(imap.tolerance, "tolerance", imap, robot),
        _per_joint(imap.duplicate, "duplicate", imap, robot),
    )


def whole_turns(d: np.ndarray, prismatic: np.ndarray | bool) -> np.ndarray:
    """The whole turns (multiples of 360 deg, 0 for prismatic joints; ``prismatic`` of d's
    last axis) nearest the joint value differences ``d``: ``d`` minus them is within
    ±180 deg, and a joint 360 deg away sits where it was."""
    return np.where(prismatic, 0.0, 360.0 * np.round(np.asarray(d, float) / 360.0))


def held_out_marked(rows: MeasuredRows, imap: ImportMap, paths: list[Path]) -> MeasuredRows:
    """A pose set's rows held out by name: the rows of ``check.files`` or of the data-row
    ranges ``check.rows`` (1-based over the files in order, before any row is dropped)
    become sweep ``check``, the others ``poses`` (``check.column``: read with the rows)."""
    from fnmatch import fnmatchcase

    c = imap.check
    if c is None or not imap.poses or not (c.files or c.ranges):
        return rows
    n = len(rows.where)
    if c.files:
        names = [p.name for p in paths]
        for pat in c.files:
            if not any(fnmatchcase(f, pat) for f in names):
                raise ImportFileError(
                    f"{imap.name}: check.files names {pat!r}, none of the given files",
                    expected="a name (or glob) of " + ", ".join(names),
                    fix="give the file on the command line, or correct check.files",
                )
        held = np.array([any(fnmatchcase(rows.file_of(k), p) for p in c.files) for k in range(n)])
    else:
        beyond = [r for r in c.ranges if r[1] > n]
        if beyond:
            raise ImportFileError(
                f"{imap.name}: check.rows {list(beyond[0])} goes beyond the {n:,} data rows",
                expected=f"row numbers 1 to {n:,} (over the files in order)",
                fix="correct check.rows",
            )
        idx = np.arange(1, n + 1)
        held = np.zeros(n, bool)
        for a, b in c.ranges:
            held |= (idx >= a) & (idx <= b)
    return replace(rows, sweep=np.where(held, CHECK_SWEEP, POSES_SWEEP).astype(np.int64))


def pose_set(rows: MeasuredRows, imap: ImportMap) -> MeasuredRows:
    """Every row a configuration of the pose set; with ``[check]``, a seeded random
    fraction of them (rounded) validation configurations instead, in file order, or the
    rows held out by name (marked by :func:`held_out_marked` or the check column)."""
    sweep = np.full(len(rows.where), POSES_SWEEP, np.int64)
    if imap.check is not None and imap.check.fraction is None:
        sweep = np.where(rows.sweep == CHECK_SWEEP, CHECK_SWEEP, POSES_SWEEP).astype(np.int64)
        m, n = int((sweep == CHECK_SWEEP).sum()), len(sweep)
        if not 0 < m < n:
            raise ImportFileError(
                f"{rows.name}: [check] holds out {m} of {n} rows",
                expected="at least one pose and one validation configuration",
                fix="correct [check] in the map",
            )
    elif imap.check is not None:
        assert imap.check.seed is not None and imap.check.fraction is not None  # with a seed
        n = len(sweep)
        m = round(imap.check.fraction * n)
        if not 0 < m < n:
            raise ImportFileError(
                f"{rows.name}: check.fraction {imap.check.fraction:g} of {n} rows "
                f"leaves {n - m} poses and {m} validation configurations",
                expected="at least one of each",
                fix="change check.fraction in the map, or drop [check]",
            )
        sweep[np.random.default_rng(imap.check.seed).permutation(n)[:m]] = CHECK_SWEEP
    return replace(rows, sweep=sweep)


def infer_sweeps(rows: MeasuredRows, robot: RobotDescription, tol: np.ndarray) -> np.ndarray:
    """Sweep of each row from consecutive rows: a run of rows in which one joint changes
    and the others hold (within ``tol``, joint values) is that joint's sweep.

    A row after which two joints change at once starts a new run; a run of one row
    that moves into another run with two joints changing belongs to no sweep and is refused.
    """
    moved = np.abs(np.diff(robot.joints_from_readings(rows.q), axis=0)) > tol  # (R-1, n)
    sweep = np.zeros(len(rows.where), np.int64)
    start = 0
    while start < len(sweep):
        end = start + 1
        joint = None
        while end < len(sweep):
            changed = np.flatnonzero(moved[end - 1])
            if len(changed) == 1 and (joint is None or changed[0] == joint):
                joint = int(changed[0])
                end += 1
            elif len(changed) == 0 and joint is not None:
                end += 1  # the same configuration again: the duplicate check names it
            else:
                break
        if joint is None:
            nxt = f" and {rows.short(end, start)}" if end < len(sweep) else ""
            coupled = "" if robot.coupling is None else ", joint values through the coupling"
            raise ImportFileError(
                f"{rows.at(start)}{nxt}: no single joint moves here "
                f"({'two or more joints change' if nxt else 'the last row stands alone'}"
                f"{coupled})",
                expected="runs of rows in which one joint moves and the others hold",
                fix="give a sweep column in the map, list the row in skip_lines, or check the "
                "robot description's [coupling] (a controller whose reading of one joint "
                "follows another's)",
            )
        if (sweep == joint + 1).any():
            raise ImportFileError(
                f"{rows.at(start)}: joint {joint + 1} is swept a second time",
                expected="one run of rows per joint",
                fix="give a sweep column in the map, or skip one run (skip_lines)",
            )
        sweep[start:end] = joint + 1
        start = end
    return sweep


def select_sweeps(
    rows: MeasuredRows, imap: ImportMap, robot: RobotDescription, tol: np.ndarray
) -> MeasuredRows:
    """Rows of each ``[[sweeps.select]]`` form that joint's sweep (a row may serve two,
    e.g. home): those whose held joints have the listed joint values (within ``tol``);
    every row in no sweep becomes a validation configuration (``check``)."""
    parts, used = [], np.zeros(len(rows.where), bool)
    n = rows.q.shape[1]
    q = robot.joints_from_readings(rows.q)
    for k, sel in enumerate(imap.select):
        beyond = [j for j in (sel.joint, *sel.held) if j > n]
        if beyond:
            raise ImportFileError(
                f"{imap.name}: sweeps.select[{k}] names joint {beyond[0]}",
                expected=f"joints 1 to {n} of the robot",
                fix="number the joints of the robot description, base to tip",
            )
        ok = np.ones(len(rows.where), bool)
        for j, value in sel.held.items():
            ok &= np.abs(q[:, j - 1] - value) <= tol[j - 1]
        used |= ok
        part = rows.take(ok)
        parts.append((part, np.full(int(ok.sum()), sel.joint, np.int64)))
    parts.append((rows.take(~used), np.full(int((~used).sum()), CHECK_SWEEP, np.int64)))
    return concat_rows([replace(p, sweep=s) for p, s in parts])


def home_readings(rows: MeasuredRows, imap: ImportMap, robot: RobotDescription) -> np.ndarray:
    """The tool configuration's readings (deg / cm): the map's ``home``, else the readings
    of each joint's median value over the other joints' sweeps (joint values, whole turns
    taken to the branch of the first such row; a joint no other sweep holds: its median
    over its own sweep)."""
    if imap.home is not None:
        if len(imap.home) != robot.n_joints:
            raise ImportFileError(
                f"{imap.name}: sweeps.home has {len(imap.home)} values",
                expected=f"{robot.n_joints} (one per joint)",
                fix="list one reading per joint",
            )
        return np.array(imap.home)
    swept = rows.sweep > 0
    q = robot.joints_from_readings(rows.q)
    home = np.zeros(robot.n_joints)
    for j in range(robot.n_joints):
        held = q[swept & (rows.sweep != j + 1), j]
        if len(held) == 0:
            held = q[rows.sweep == j + 1, j]
        home[j] = np.median(held - whole_turns(held - held[0], robot.prismatic[j]))
    return robot.readings_from_joints(home)
