"""Targets fixed in the world (reflectors on the base or the floor, ``fixed = true``):
measured at every pose to follow the tracker's drift, never points of the arm.

Their readings register each pose's points into one tracker frame: the rigid motion
(:func:`pipeline.kinematics.alignment.register_rigid`) taking the pose's fixed readings
onto their reference positions (each target's median reading over the poses) is applied
to the pose's arm points (and a measured orientation). With ``fixed_block = k`` in the
map, each pose is registered by the fixed readings of the k poses around it (a centred
window, in file order): the drift is slow, and k poses' readings average the tracker's
noise, which one pose's three reflectors carry to the arm's points over their lever (the
reflectors span ~1 m, the arm reaches beyond them; docs/import.md, Fixed targets, has
the measured effect). A pose whose window holds fewer than three fixed targets takes the
registration of the last pose before it that had three; one before any is used
uncorrected and counted.
Whether the registration is applied is ``fixed_correction`` in the map: ``"auto"`` (the
default) applies it only when the fixed readings move beyond their noise
(:func:`pipeline.importers.fixed_motion.motion_test`, 1 % false alarms): without drift
it only carries the readings' noise onto the arm's points (docs/import.md has the
measured cost); ``"always"`` and ``"never"`` force the choice. The line says which way
it went and why (the statistic and its threshold).
A fixed target that moves against the others (its distance from the registered reference
beyond :data:`MOVED_CM`) is refused in one line naming the file, the line and the target.
The drift (each pose's RMS distance of its fixed readings from the reference, before
correction) and the residual after it are recorded per pose (``tracker_drift_cm``,
``tracker_residual_cm``: the ``joints`` table; the residual NaN when the registration is
not applied) and summed up in one line.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.errors import ImportFileError
from pipeline.importers.fixed_motion import MotionTest, motion_test
from pipeline.importers.mapping import ImportMap
from pipeline.importers.rows import MeasuredRows
from pipeline.kinematics.alignment import register_rigid

#: A fixed target whose reading lies this far (cm) from its registered reference has
#: moved (knocked, re-seated), not drifted: 0.5 cm is 100 times a tracker's drift over a
#: session (0.05 mm) and far below a reflector knocked off its nest.
MOVED_CM = 0.5


def fixed_ids(imap: ImportMap) -> list[str]:
    """The ids of the map's targets fixed in the world."""
    return [t.id for t in imap.targets if t.fixed]


def registered(rows: MeasuredRows, imap: ImportMap) -> MeasuredRows:
    """``rows`` with each pose's arm points registered by its fixed targets' readings, the
    fixed targets removed, and the drift recorded (module docstring); unchanged without
    fixed targets."""
    ids = fixed_ids(imap)
    if not ids:
        return rows
    fixed = np.stack([rows.targets[t] for t in ids], axis=1)  # (R, F, 3)
    seen = np.isfinite(fixed).all(axis=2)  # (R, F)
    if not seen.any(axis=0).all():
        t = ids[int(np.flatnonzero(~seen.any(axis=0))[0])]
        raise ImportFileError(
            f"{rows.name}: fixed target {t} has no reading in any row",
            expected="a reading of each fixed target at some poses",
            fix="check its columns in the map",
        )
    ref = np.array([np.median(fixed[seen[:, f], f], axis=0) for f in range(len(ids))])
    n, k = len(rows.where), imap.fixed_block
    drift, resid = np.full(n, np.nan), np.full(n, np.nan)
    T_of: list[np.ndarray | None] = [None] * n
    last: np.ndarray | None = None
    own = 0
    for r in range(n):
        window = np.arange(max(0, r - k // 2), min(n, r - k // 2 + k))  # k poses around r
        r_at, f_at = np.nonzero(seen[window])
        T = None
        if len(set(f_at.tolist())) >= 3:  # three distinct fixed targets read around r
            T = register_rigid(fixed[window[r_at], f_at], ref[f_at])
        if T is not None:
            own += 1
            _refuse_moved(rows, ids, r, seen, fixed, ref, T, resid)
            last = T
        T_of[r] = last
        idx = np.flatnonzero(seen[r])
        if len(idx):
            drift[r] = float(np.sqrt(np.mean(np.sum((fixed[r, idx] - ref[idx]) ** 2, axis=1))))
    apply, why = _decided(imap.fixed_correction, motion_test(fixed, ref, k))
    arm = {t: p.copy() for t, p in rows.targets.items() if t not in ids}
    wxyz = None if rows.orientation_wxyz is None else rows.orientation_wxyz.copy()
    for r, T in enumerate(T_of if apply else ()):
        if T is None:
            continue
        for p in arm.values():
            p[r] = T[:3, :3] @ p[r] + T[:3, 3]
        if wxyz is not None and np.isfinite(wxyz[r]).all():
            wxyz[r] = _rotated(T[:3, :3], wxyz[r])
    uncorrected = sum(T is None for T in T_of)
    ok = drift[np.isfinite(drift)]
    how = "each pose" if k == 1 else f"windows of {k} poses"
    done = (
        f"registered {own} poses by their own readings ({how}), {n - own - uncorrected} by "
        f"an earlier one, {uncorrected} uncorrected"
        if apply
        else "every pose used uncorrected"
    )
    note = (
        f"{rows.name}: fixed targets {', '.join(ids)}: {why}; {done}; drift median "
        f"{np.median(ok) if len(ok) else float('nan'):.3g} cm, max "
        f"{ok.max() if len(ok) else float('nan'):.3g} cm"
    )
    if not apply:
        resid[:] = np.nan  # not registered at any pose
    sigma = None if rows.sigma is None else {t: s for t, s in rows.sigma.items() if t in arm}
    return replace(
        rows,
        targets=arm,
        sigma=sigma,
        orientation_wxyz=wxyz,
        drift_cm=drift,
        residual_cm=resid,
        notes=(*rows.notes, note),
    )


def _decided(how: str, test: MotionTest | None) -> tuple[bool, str]:
    """Whether to apply the registration (``fixed_correction`` ``how``, the fixed
    readings' ``test``), and why in words."""
    said = "not tested: too few readings, or none scattered" if test is None else test.words()
    if how != "auto":
        return how == "always", f'fixed_correction = "{how}" ({said})'
    if test is None:
        return True, f"corrected ({said})"
    if test.moved:
        return True, f"drift beyond their noise, corrected ({said})"
    return False, (
        f'no drift beyond their noise, not corrected ({said}; fixed_correction = "always" '
        "forces it)"
    )


def _refuse_moved(
    rows: MeasuredRows,
    ids: list[str],
    r: int,
    seen: np.ndarray,
    fixed: np.ndarray,
    ref: np.ndarray,
    T: np.ndarray,
    resid: np.ndarray,
) -> None:
    """Pose r's fixed readings' RMS distance from the reference after ``T`` into
    ``resid``; a fixed target beyond :data:`MOVED_CM` is refused in one line."""
    idx = np.flatnonzero(seen[r])
    if not len(idx):
        return
    dist = np.linalg.norm(fixed[r, idx] @ T[:3, :3].T + T[:3, 3] - ref[idx], axis=1)
    if dist.max() > MOVED_CM:
        j = int(np.argmax(dist))
        raise ImportFileError(
            f"{rows.at(r)}: fixed target {ids[idx[j]]} is {dist[j]:.3g} cm from where the "
            "other fixed targets put it (it moved)",
            expected=f"fixed targets that hold still together (within {MOVED_CM:g} cm after "
            "registering the pose)",
            fix="drop fixed = true from a target that is not fixed, or split the file where it "
            "was moved",
        )
    resid[r] = float(np.sqrt(np.mean(dist**2)))


def _rotated(R: np.ndarray, wxyz: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of ``R`` times the rotation ``wxyz``."""
    from scipy.spatial.transform import Rotation

    q = (Rotation.from_matrix(R) * Rotation.from_quat(wxyz[[1, 2, 3, 0]])).as_quat()
    return np.asarray(q[[3, 0, 1, 2]], float)
