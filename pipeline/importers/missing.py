"""Rows without a measurement, and σ below the tracker's resolution.

A tracker that lost the beam leaves empty or ``nan`` cells. Such a row is dropped and
counted per column, and the count is said in one ``warning:`` line naming the file and
the first lines (``--strict``: refused in one line instead). A σ column whose value
rounds to zero (or lies below ``sigma_floor``) is raised to the floor, counted and said,
rather than refused: a σ of 0 would weigh the point infinitely.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.layout import ordered_targets, sigma_columns
from pipeline.importers.mapping import ImportMap
from pipeline.importers.rows import LENGTH_CM, MeasuredRows

#: A σ column's floor when the map states none: 0.001 mm, the last digit a tracker's
#: software prints in mm (three decimals); a σ printed as 0.000 is below it.
SIGMA_FLOOR_MM = 0.001
_SHOWN = 5  # lines named in a message


def _columns(rows: MeasuredRows, imap: ImportMap) -> list[tuple[str, np.ndarray]]:
    """Each measured column's name (as the map gives it) and its values (R,)."""
    out = [(str(j.column), rows.q[:, k]) for k, j in enumerate(imap.joints)]
    for t in ordered_targets(imap):
        if t.fixed:
            continue  # a fixed target's lost reading: the pose is registered by its block
        out += [(str(c), rows.targets[t.id][:, a]) for a, c in enumerate((t.x, t.y, t.z))]
        s = sigma_columns(t)
        if s is not None and rows.sigma is not None:
            out += [(str(c), rows.sigma[t.id][:, a]) for a, c in enumerate(s)]
    if imap.orientation is not None and rows.orientation_wxyz is not None:
        ok = np.isfinite(rows.orientation_wxyz).all(axis=1).astype(float)
        ok[ok == 0] = np.nan
        out.append(("/".join(map(str, imap.orientation.columns)), ok))
    return out


def without_missing(rows: MeasuredRows, imap: ImportMap, strict: bool) -> MeasuredRows:
    """``rows`` without those holding a missing or non-finite measured value; their count
    per column goes to ``rows.notes``. ``strict``: refused in one line instead."""
    cols = _columns(rows, imap)
    bad_of = {name: ~np.isfinite(v) for name, v in cols}
    bad = np.zeros(len(rows.where), bool)
    for b in bad_of.values():
        bad |= b
    if not bad.any():
        return rows
    idx = np.flatnonzero(bad)
    counts = {n: int(b.sum()) for n, b in bad_of.items() if b.any()}
    per = ", ".join(f"{n} {c}" for n, c in counts.items())
    first = ", ".join(rows.at(k) for k in idx[:_SHOWN]) + (", ..." if len(idx) > _SHOWN else "")
    if strict:
        raise ImportFileError(
            f"{rows.at(idx[0])}: a measured value is missing or not a finite number "
            f"({len(idx)} such rows; by column: {per})",
            expected="a finite value in every measured column of every row (--strict)",
            fix="drop --strict to import without these rows, or complete them",
        )
    note = (f"{rows.name}: {len(idx)} of {len(rows.where)} rows dropped, a measured value "
            f"missing or not finite (by column: {per}): {first}")  # fmt: skip
    kept = rows.take(~bad)
    return replace(kept, notes=(*rows.notes, note), dropped=rows.dropped + len(idx))


def sigma_floored(rows: MeasuredRows, imap: ImportMap) -> MeasuredRows:
    """σ from columns below the floor (the map's ``sigma_floor``, else
    :data:`SIGMA_FLOOR_MM`) raised to it, counted in ``rows.notes``."""
    if rows.sigma is None or imap.sigma is not None:
        return rows  # no σ columns (none, or the map's one stated σ)
    unit = "mm" if imap.sigma_floor is None else imap.length_unit
    value = SIGMA_FLOOR_MM if imap.sigma_floor is None else imap.sigma_floor
    floor = value * LENGTH_CM[unit]
    low = {t: (s >= 0) & (s < floor) for t, s in rows.sigma.items()}  # s < 0: refused later
    n = sum(int(v.any(axis=1).sum()) for v in low.values())  # points
    if n == 0:
        return rows
    sigma = {t: np.where(low[t], floor, s) for t, s in rows.sigma.items()}
    note = (f"{rows.name}: the σ of {n} point(s) below the floor {value:g} {unit}, raised to "
            "it (map: sigma_floor)")  # fmt: skip
    return replace(rows, sigma=sigma, notes=(*rows.notes, note))
