"""Which rows form which joint's sweep (a sweep column, ``infer``, or a selection), or
the pose set (every row, a seeded fraction of them validation configurations).

A file holds the controller's readings; which joint moves and which holds is a matter of
joint values, the readings through the robot's coupling when it has one
(:meth:`~pipeline.robots.description.RobotDescription.joints_from_readings`): a coupled
controller's elbow reading follows the shoulder while the elbow itself holds."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.mapping import ImportMap
from pipeline.importers.rows import MeasuredRows, Tolerances
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


def pose_set(rows: MeasuredRows, imap: ImportMap) -> MeasuredRows:
    """Every row a configuration of the pose set; with ``[check]``, a seeded random
    fraction of them (rounded) validation configurations instead, in file order."""
    sweep = np.full(len(rows.where), POSES_SWEEP, np.int64)
    if imap.check is not None:
        n = len(sweep)
        m = round(imap.check.fraction * n)
        if not 0 < m < n:
            raise ImportFileError(
                f"{rows.source.name}: check.fraction {imap.check.fraction:g} of {n} rows "
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
    src = rows.source.name
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
            nxt = f" and {rows.where[end]}" if end < len(sweep) else ""
            coupled = "" if robot.coupling is None else ", joint values through the coupling"
            raise ImportFileError(
                f"{src}: {rows.where[start]}{nxt}: no single joint moves here "
                f"({'two or more joints change' if nxt else 'the last row stands alone'}"
                f"{coupled})",
                expected="runs of rows in which one joint moves and the others hold",
                fix="give a sweep column in the map, list the row in skip_lines, or check the "
                "robot description's [coupling] (a controller whose reading of one joint "
                "follows another's)",
            )
        if (sweep == joint + 1).any():
            raise ImportFileError(
                f"{src}: {rows.where[start]}: joint {joint + 1} is swept a second time",
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
        parts.append((part, np.full(int(ok.sum()), sel.joint)))
    parts.append((rows.take(~used), np.full(int((~used).sum()), CHECK_SWEEP)))
    return _concat(parts)


def _concat(parts: list[tuple[MeasuredRows, np.ndarray]]) -> MeasuredRows:
    first = parts[0][0]
    orient = (
        None
        if first.orientation_wxyz is None
        else np.vstack(
            [p.orientation_wxyz for p, _ in parts]  # type: ignore[misc]
        )
    )
    sigma = (
        None
        if first.sigma is None
        else {t: np.vstack([p.sigma[t] for p, _ in parts]) for t in first.sigma}  # type: ignore[index]
    )
    return MeasuredRows(
        source=first.source,
        where=tuple(w for p, _ in parts for w in p.where),
        sweep=np.concatenate([s for _, s in parts]),
        q=np.vstack([p.q for p, _ in parts]),
        targets={t: np.vstack([p.targets[t] for p, _ in parts]) for t in first.targets},
        orientation_wxyz=orient,
        sigma=sigma,
    )


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
