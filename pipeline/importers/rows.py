"""Measured rows: what every import format is parsed into before it becomes a session.

One row per measured configuration: the source position (for error messages), the
sweep it belongs to, the joint readings (deg / cm) and the measured target
positions (cm). :func:`checked_rows` refuses what would give a wrong session, with
one line naming the file, the line and what to do.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, overload

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.robots.description import RobotDescription
from pipeline.stages.recording import CHECK_SWEEP, LIMIT_MARGIN, POSES_SWEEP
from pipeline.stages.recording_points import MAX_COORD_CM, MIN_SIGMA_CM

#: Length units of imported points and prismatic readings -> cm.
LENGTH_CM = {"mm": 0.1, "cm": 1.0, "m": 100.0}
#: Angle units of revolute readings -> deg.
ANGLE_DEG = {"deg": 1.0, "rad": float(np.rad2deg(1.0))}


class Places(Sequence[str]):
    """Rows' places in their files as :attr:`MeasuredRows.where` holds them ("line 12"),
    each formed when asked: a million rows' strings cost 0.3 s (issue 45)."""

    def __init__(self, word: str, numbers: np.ndarray) -> None:
        self.word, self.numbers = word, numbers

    def __len__(self) -> int:
        return len(self.numbers)

    @overload
    def __getitem__(self, k: int) -> str: ...
    @overload
    def __getitem__(self, k: slice) -> Sequence[str]: ...
    def __getitem__(self, k: int | slice) -> str | Sequence[str]:
        if isinstance(k, slice):
            return Places(self.word, self.numbers[k])
        return f"{self.word} {self.numbers[k]}"

    def take(self, idx: np.ndarray) -> Places:
        """The places of rows ``idx``."""
        return Places(self.word, self.numbers[idx])


def _places(parts: list[Sequence[str]]) -> Sequence[str]:
    """The places of ``parts`` one after the other."""
    places = [p for p in parts if isinstance(p, Places)]
    if len(places) == len(parts) and len({p.word for p in places}) == 1:
        return Places(places[0].word, np.concatenate([p.numbers for p in places]))
    return tuple(w for p in parts for w in p)


@dataclass(frozen=True)
class MeasuredRows:
    """Rows of a foreign file, in armsig's units.

    Attributes
    ----------
    source : Path
        The foreign file.
    where : sequence of str, shape (R,)
        Each row's place in the file ("line 12", "entry '1593701755'").
    sweep : ndarray of int, shape (R,)
        Swept joint (1-based), or ``CHECK_SWEEP`` for a validation configuration.
    q : ndarray, shape (R, n)
        Joint readings, deg (revolute) / cm (prismatic).
    targets : dict of str to ndarray, shape (R, 3)
        Target id -> measured position, cm, sensor frame.
    orientation_wxyz : ndarray, shape (R, 4), optional
        Unit quaternion of a 6-D target frame (the first target), when measured.
    orientation_sigma_deg : float, optional
        Its stated σ per rotation-vector component (deg).
    sigma : dict of str to ndarray, shape (R, 3), optional
        Target id -> standard deviation of x, y, z (cm), when the file states it.
    payload_kg : ndarray, shape (R,), optional
        The payload on the flange (kg) at each row, when the map states it.
    files : tuple of str, shape (R,)
        Each row's source file name (empty: every row is ``source``'s).
    lines : ndarray of int, shape (R,), optional
        Each row's line in its file (1-based, as an editor numbers it; 0: no line, a
        YAML entry), recorded as ``source_line``.
    notes : tuple of str
        Lines for the user: rows dropped for a missing value, σ raised to the floor,
        a bag's samples taken while the arm moved.
    dropped : int
        How many rows were dropped for a missing value.
    drift_cm, residual_cm : ndarray, shape (R,), optional
        With fixed targets (:mod:`pipeline.importers.fixed`): each pose's RMS distance of
        their readings from their reference before the correction, and after it (NaN:
        not registered at this pose).
    """

    source: Path
    where: Sequence[str]  # a tuple, or Places (a table's lines, formed when asked)
    sweep: np.ndarray
    q: np.ndarray
    targets: dict[str, np.ndarray]
    orientation_wxyz: np.ndarray | None = None
    sigma: dict[str, np.ndarray] | None = None
    orientation_sigma_deg: float | None = None
    payload_kg: np.ndarray | None = None
    files: tuple[str, ...] = ()
    lines: np.ndarray | None = None
    notes: tuple[str, ...] = ()  # one line each for the user (rows dropped, σ floored)
    dropped: int = 0  # rows dropped for a missing value
    drift_cm: np.ndarray | None = None  # (R,) fixed targets' RMS drift before correction
    residual_cm: np.ndarray | None = None  # (R,) their RMS residual after it (NaN: none)

    def file_of(self, k: int) -> str:
        """Row ``k``'s source file name."""
        return self.files[k] if self.files else self.source.name

    def at(self, k: int) -> str:
        """Row ``k``'s place for a message: ``"b.csv: line 12"``."""
        return f"{self.file_of(k)}: {self.where[k]}"

    def short(self, k: int, beside: int) -> str:
        """Row ``k``'s place after row ``beside``'s: its line alone in the same file."""
        return self.where[k] if self.file_of(k) == self.file_of(beside) else self.at(k)

    @property
    def name(self) -> str:
        """The source for a message: the file, or the first and the count of several."""
        names = dict.fromkeys(self.files or (self.source.name,))
        first = next(iter(names))
        return first if len(names) == 1 else f"{first} (+{len(names) - 1} files)"

    def take(self, keep: np.ndarray) -> MeasuredRows:
        """The rows ``keep`` (indices or mask), in that order."""
        idx = np.arange(len(self.where))[keep]
        return replace(
            self,
            where=self.where.take(idx)
            if isinstance(self.where, Places)
            else tuple(self.where[k] for k in idx),
            sweep=self.sweep[idx],
            q=self.q[idx],
            targets={t: p[idx] for t, p in self.targets.items()},
            orientation_wxyz=None if self.orientation_wxyz is None else self.orientation_wxyz[idx],
            sigma=None if self.sigma is None else {t: s[idx] for t, s in self.sigma.items()},
            payload_kg=None if self.payload_kg is None else self.payload_kg[idx],
            files=tuple(self.files[k] for k in idx) if self.files else (),
            lines=None if self.lines is None else self.lines[idx],
            drift_cm=None if self.drift_cm is None else self.drift_cm[idx],
            residual_cm=None if self.residual_cm is None else self.residual_cm[idx],
        )

    def with_sigma(self, sigma_cm: float | None) -> MeasuredRows:
        """These rows with one stated σ (cm) of every coordinate of every target (a map's
        ``sigma``); unchanged when None."""
        if sigma_cm is None:
            return self
        n = len(self.where)
        return replace(self, sigma={t: np.full((n, 3), sigma_cm) for t in self.targets})


def concat_rows(parts: list[MeasuredRows]) -> MeasuredRows:
    """The rows of ``parts`` one after the other (several files, or a selection's sweeps),
    each keeping its source file and line; an optional array kept only when every part
    has it (a map reads every file alike)."""
    first = parts[0]
    if len(parts) == 1:
        return first

    def stacked(get: Any) -> Any:
        vals = [get(p) for p in parts]
        return None if any(v is None for v in vals) else np.concatenate(vals)

    sigma = None
    if first.sigma is not None and all(p.sigma is not None for p in parts):
        sigma = {t: np.concatenate([p.sigma[t] for p in parts]) for t in first.sigma}  # type: ignore[index]
    return replace(
        first,
        where=_places([p.where for p in parts]),
        sweep=np.concatenate([p.sweep for p in parts]),
        q=np.concatenate([p.q for p in parts]),
        targets={t: np.concatenate([p.targets[t] for p in parts]) for t in first.targets},
        orientation_wxyz=stacked(lambda p: p.orientation_wxyz),
        sigma=sigma,
        payload_kg=stacked(lambda p: p.payload_kg),
        files=tuple(f for p in parts for f in (p.files or (p.source.name,) * len(p.where))),
        lines=stacked(lambda p: p.lines),
        notes=tuple(n for p in parts for n in p.notes),
        dropped=sum(p.dropped for p in parts),
        drift_cm=stacked(lambda p: p.drift_cm),
        residual_cm=stacked(lambda p: p.residual_cm),
    )


@dataclass(frozen=True)
class Tolerances:
    """Per joint, joint values (deg / cm): ``held``, how far a joint that holds may read
    from its value (sweep inference, selection, the held-joint check, home); ``duplicate``,
    two stops of a sweep whose swept joint is within it are one configuration measured
    twice."""

    held: np.ndarray
    duplicate: np.ndarray


def unit_factor(unit: str, table: dict[str, float], what: str, where: str) -> float:
    """The factor of ``unit`` in ``table`` (to cm or deg); an unknown unit is refused."""
    if unit not in table:
        raise ImportFileError(
            f"{where}: unknown {what} unit {unit!r}",
            expected=" | ".join(table),
            fix=f"write the {what} unit as one of {', '.join(table)}",
        )
    return table[unit]


def readings_in_boundary_units(
    values: np.ndarray, units: list[str], robot: RobotDescription, where: str
) -> np.ndarray:
    """Readings (R, n) in the file's per-joint units -> deg / cm, by the robot's joint types."""
    out = np.array(values, float)
    for j, (unit, spec) in enumerate(zip(units, robot.joints, strict=True)):
        table = LENGTH_CM if spec.prismatic else ANGLE_DEG
        kind = "prismatic joint" if spec.prismatic else "revolute joint"
        out[:, j] *= unit_factor(unit, table, f"{kind} {spec.name!r}", where)
    return out


def refuse_absurd_coordinates(rows: MeasuredRows) -> None:
    """Refuse a finite coordinate farther from the sensor than the recording contract
    takes (:data:`~pipeline.stages.recording_points.MAX_COORD_CM`, ±1,000 m), in one line
    naming the row, before any linear algebra sees it: ``validate --against`` reads a
    file without a recording (a coordinate of 1e308 made its registration's SVD spin or
    fail, issue 44); ``import`` refuses such a recording as identify would."""
    for t, p in rows.targets.items():
        far = np.flatnonzero((np.abs(p) > MAX_COORD_CM).any(axis=1) & np.isfinite(p).all(axis=1))
        if len(far):
            k = far[0]
            raise ImportFileError(
                f"{rows.source.name}: {rows.where[k]}: target {t} lies "
                f"{np.abs(p[k]).max():g} cm from the sensor",
                expected=f"coordinates within {MAX_COORD_CM:g} cm (the recording contract's)",
                fix="check the cell and the map's length_unit",
            )


def checked_rows(rows: MeasuredRows, robot: RobotDescription, tol: Tolerances) -> MeasuredRows:
    """Refuse rows that would make a wrong session; ``tol``: how far a held joint may be
    from its sweep's median, how close two stops of a sweep may be (joint values: the
    readings through the robot's coupling).

    Refused: a non-finite value; a σ that is not positive or under 1 nm; a joint value
    outside its limits; a row measured twice (same sweep, the swept joint within
    ``tol.duplicate``); a joint without a sweep (unless the rows are a pose set) or whose
    sweep does not move it; a sweep in which another joint moves too.
    """
    src = rows.name
    extra = [] if rows.orientation_wxyz is None else [rows.orientation_wxyz]
    sigma = [] if rows.sigma is None else list(rows.sigma.values())
    values = np.column_stack([rows.q, *rows.targets.values(), *extra, *sigma])
    bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
    if len(bad):
        raise ImportFileError(
            f"{rows.at(bad[0])}: a value is missing or not a number (NaN)",
            expected="finite joint readings, coordinates, angles and σ in every row",
            fix="delete the row, or mark it as skipped in the map",
        )
    small = np.flatnonzero((np.column_stack(sigma) <= 0).any(axis=1)) if sigma else np.zeros(0)
    if len(small):
        raise ImportFileError(
            f"{rows.at(small[0])}: a point's σ is zero or negative",
            expected="a positive standard deviation of every coordinate",
            fix="correct the σ column, or state one σ for the file (map: sigma = ...)",
        )
    tiny: Any = np.flatnonzero((np.column_stack(sigma) < MIN_SIGMA_CM).any(axis=1)) if sigma else []
    if len(tiny):
        raise ImportFileError(
            f"{src}: {rows.where[tiny[0]]}: a point's σ is under 1 nm",
            expected=f"a standard deviation of at least {MIN_SIGMA_CM:g} cm, in the map's "
            "length_unit",
            got=f"{np.column_stack(sigma)[tiny[0]].min():g} cm",
            fix="correct the σ column or the map's sigma (and its length_unit)",
        )
    names = [j.name for j in robot.joints]
    values = robot.joints_from_readings(rows.q)
    coupled = "" if robot.coupling is None else " (through the coupling)"
    what = "reading" if robot.coupling is None else "joint value"
    lim = robot.limits
    out = np.argwhere((values < lim[:, 0] - LIMIT_MARGIN) | (values > lim[:, 1] + LIMIT_MARGIN))
    if len(out):
        k, j = out[0]
        unit = robot.joints[j].unit
        raise ImportFileError(
            f"{rows.at(k)}: joint {j + 1} ({names[j]}) reads {values[k, j]:g} "
            f"{unit}{coupled}, outside its limits",
            expected=f"{lim[j, 0]:g} to {lim[j, 1]:g} {unit} (± {LIMIT_MARGIN:g})",
            fix="check the joint's unit and unwrap setting in the map, or the robot's limits",
        )
    pose_set = bool((rows.sweep == POSES_SWEEP).any())
    for j in range(robot.n_joints):
        sel = np.flatnonzero(rows.sweep == j + 1)
        if len(sel) == 0 and pose_set:
            continue  # a pose set moves every joint: the fit says which it cannot identify
        if len(sel) == 0:
            raise ImportFileError(
                f"{src}: joint {j + 1} ({names[j]}) never moves alone (no sweep)",
                expected="rows where this joint moves alone",
                fix="add its sweep, or check the sweep column / map",
            )
        q = values[sel]
        if np.ptp(q[:, j]) <= tol.held[j]:
            raise ImportFileError(
                f"{src}: joint {j + 1} ({names[j]}) never moves in its sweep "
                f"({rows.where[sel[0]]} on)",
                expected=f"readings spread by more than {tol.held[j]:g}",
                fix="check the joint's column and the sweep column of the map",
            )
        order = np.argsort(q[:, j], kind="stable")
        same = np.flatnonzero(np.abs(np.diff(q[order, j])) <= tol.duplicate[j])
        if len(same):
            a, b = sel[order[same[0]]], sel[order[same[0] + 1]]
            raise ImportFileError(
                f"{rows.at(a)} and {rows.short(b, a)} measure joint {j + 1} "
                f"({names[j]}) at the same {what} {q[order[same[0]], j]:g}",
                expected=f"each configuration of a sweep once (duplicated rows: within "
                f"{tol.duplicate[j]:g}, the map's sweeps.duplicate)",
                fix="delete one of the two rows (or average them)",
            )
        held = np.abs(q - np.median(q, axis=0)) > tol.held
        held[:, j] = False
        if held.any():
            k, m = np.argwhere(held)[0]
            raise ImportFileError(
                f"{rows.at(sel[k])}: joint {m + 1} ({names[m]}) moves in the sweep "
                f"of joint {j + 1} ({what} {q[k, m]:g}, median {np.median(q[:, m]):g}"
                f"{coupled})",
                expected=f"one joint moving per sweep, the others within {tol.held[m]:g} "
                "(the map's sweeps.tolerance)",
                fix="split the rows into one sweep per joint, raise the map's tolerance, or "
                "check the robot description's [coupling]",
            )
    unknown = np.flatnonzero(
        ~np.isin(rows.sweep, [CHECK_SWEEP, POSES_SWEEP, *range(1, robot.n_joints + 1)])
    )
    if len(unknown):
        k = unknown[0]
        raise ImportFileError(
            f"{rows.at(k)}: sweep {rows.sweep[k]} names no joint of {robot.name}",
            expected=f"joint 1 to {robot.n_joints}",
            fix="check the joint numbering and the robot description",
        )
    return rows
