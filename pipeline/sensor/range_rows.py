"""The raw slant ranges a range-level fit uses, read from the ``ranges`` table by key.

Two kinds of rows (Appendix E):

- *target* rows: sparker 5 → microphone A, B, C or D, one per echo, tied to the
  (sweep, step) target position they observe;
- *rod* rows: sparkers 1, 2 → B and 3, 4 → D (E.1), tied to no position. The rod
  sparkers' ranges to the other microphones run along lines that are not level and
  whose end points the recording does not calibrate (only the rod length is); they
  are left out.

Missing echoes (null ranges) give no row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.compute as pc

from pipeline.errors import ArmsigError
from pipeline.sensor.compensation import rod_ratios
from pipeline.sensor.geometry import MICROPHONES, DigitizerGeometry
from pipeline.sensor.speed_spline import FINEST_S
from pipeline.sweeps import sweep_id, sweep_name

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

TARGET_SPARKER = 5
#: Rod sparker (1-based) → the microphone (index into A-D) it is rigid with (E.1).
ROD_MICROPHONE = {1: 1, 2: 1, 3: 3, 4: 3}
_COLUMNS = ("sweep", "step", "repeat", "sparker", "microphone", "range_cm", "t_s")
_FIX = "re-run the ranges stage of a sonic session (pipeline identify NAME)"


@dataclass(frozen=True)
class RangeRows:
    """The echoes of one session, split into target and rod rows.

    Attributes
    ----------
    key_sweep, key_step : ndarray of int, shape (K,)
        The observed (sweep, step) target positions, sorted.
    t_pos, t_mic : ndarray of int, shape (Rt,)
        Target rows: index into the keys, microphone index (0-3 = A-D).
    t_s_cm, t_time_s : ndarray, shape (Rt,)
        Their measured ranges (cm) and cycle times (s).
    r_mic, r_sparker : ndarray of int, shape (Rr,)
        Rod rows: microphone index (1 = B, 3 = D) and sparker (1-4).
    r_s_cm, r_time_s : ndarray, shape (Rr,)
        Their measured ranges and cycle times.
    f_b, f_d, cycle_t_s : ndarray, shape (M,)
        Per-cycle rod speed ratios (E.1) (NaN where an echo is missing) and times.
    """

    key_sweep: IntArray
    key_step: IntArray
    t_pos: IntArray
    t_mic: IntArray
    t_s_cm: Array
    t_time_s: Array
    r_mic: IntArray
    r_sparker: IntArray
    r_s_cm: Array
    r_time_s: Array
    f_b: Array
    f_d: Array
    cycle_t_s: Array


def _column(table: pa.Table, name: str) -> np.ndarray:
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False))


def unique_rows(a: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Sorted unique rows of small-integer keys (M, k) and each row's index into them:
    ``np.unique(a, axis=0, return_inverse=True)`` through one int64 key per row."""
    lo = a.min(axis=0) if len(a) else np.zeros(a.shape[1], np.int64)
    span = (a.max(axis=0) - lo + 1) if len(a) else np.ones(a.shape[1], np.int64)
    code = np.zeros(len(a), np.int64)
    for k in range(a.shape[1]):  # mixed radix; keys are sweep/step/repeat counts, far below 2**63
        code = code * span[k] + (a[:, k] - lo[k])
    _, first, inverse = np.unique(code, return_index=True, return_inverse=True)
    return a[first], inverse.reshape(-1).astype(np.int64)


def range_rows(ranges: pa.Table, geometry: DigitizerGeometry) -> RangeRows:
    """Split the ``ranges`` stage table into target and rod rows, joined by key.

    Raises
    ------
    ArmsigError
        Columns missing, a microphone outside A-D, no rod ranges at B or at D, or a
        microphone that never heard the target.
    """
    missing = [c for c in _COLUMNS if c not in ranges.column_names]
    if missing:
        raise ArmsigError(
            "the ranges table lacks columns",
            expected=", ".join(_COLUMNS),
            got=f"no {', '.join(missing)}",
            fix=_FIX,
        )
    sweep, step, repeat = (_column(ranges, c).astype(np.int64) for c in ("sweep", "step", "repeat"))
    sparker = _column(ranges, "sparker").astype(np.int64)
    s = _column(ranges, "range_cm").astype(float)
    t = _column(ranges, "t_s").astype(float)
    names = ranges.column("microphone")
    mic_arr = pc.index_in(names, value_set=pa.array(MICROPHONES))
    mic = np.asarray(mic_arr.to_numpy(zero_copy_only=False), float)
    if np.isnan(mic).any():
        bad = names.filter(pc.is_null(mic_arr)).to_pylist()[0]
        raise ArmsigError(
            "the ranges table names an unknown microphone",
            expected="microphone A, B, C or D",
            got=repr(bad),
            fix=_FIX,
        )
    mic = mic.astype(np.int64)
    heard = np.isfinite(s)
    tgt = heard & (sparker == TARGET_SPARKER)
    rod_mic = np.array([ROD_MICROPHONE.get(int(k), -1) for k in range(6)])[np.clip(sparker, 0, 5)]
    rod = heard & (sparker >= 1) & (sparker <= 4) & (mic == rod_mic)
    for k in (1, 3):
        if not (rod & (mic == k)).any():
            raise ArmsigError(
                f"no calibration-rod ranges at microphone {MICROPHONES[k]}",
                expected="ranges of sparkers 1, 2 → B and 3, 4 → D (Appendix E.1)",
                got="none heard",
                fix="check the rods' sparkers and microphone cables, then re-record",
            )
    for k, m in enumerate(MICROPHONES):
        if not (tgt & (mic == k)).any():
            raise ArmsigError(
                f"microphone {m} never heard the target sparker",
                expected="target ranges (sparker 5) at each of microphones A, B, C, D",
                got=f"none at {m} among {int(tgt.sum())} target echoes",
                fix=f"check microphone {m} and its cable, then re-record",
            )
    keys, t_pos = unique_rows(np.stack([sweep[tgt], step[tgt]], axis=1))
    # Per-cycle rod ratios (E.1), joined by the (sweep, step, repeat) cycle key.
    cyc, c_idx = unique_rows(np.stack([sweep, step, repeat], axis=1))
    rod_s = np.full((len(cyc), 4), np.nan)
    rod_s[c_idx[rod], sparker[rod] - 1] = s[rod]
    cycle_t = np.zeros(len(cyc))
    cycle_t[c_idx] = t
    f_b, f_d = rod_ratios(rod_s[:, 0:2], rod_s[:, 2:4], geometry.rod_length_cm)
    return RangeRows(
        key_sweep=keys[:, 0],
        key_step=keys[:, 1],
        t_pos=t_pos,
        t_mic=mic[tgt],
        t_s_cm=s[tgt],
        t_time_s=t[tgt],
        r_mic=mic[rod],
        r_sparker=sparker[rod],
        r_s_cm=s[rod],
        r_time_s=t[rod],
        f_b=f_b,
        f_d=f_d,
        cycle_t_s=cycle_t,
    )


#: How far a cycle's time may run back behind a cycle measured before it (s): a logger's
#: or a clock's jitter. The speed of sound drifts over minutes, and its spline needs the
#: times only to a fraction of its finest knot spacing (:data:`FINEST_S`, 15 s): a third
#: of it moves no knot's share of the data far. A clock of another implementation of the
#: recording contract with σ 0.4 s of jitter runs back by up to ~2.5 s over a few thousand
#: cycles (the fixed 2 s before refused it, issue 44); a permuted or reversed clock runs
#: back by minutes.
CLOCK_JITTER_S = FINEST_S / 3.0


def check_cycle_order(ranges: pa.Table, order: list[int | str]) -> None:
    """Refuse cycle times that are not a clock of the recorded measurement order.

    The range model's speed of sound is a function of the cycles' times (their values:
    the ``/sonic/ranges`` measurement times, :mod:`pipeline.contract.mcap_read`). The rig
    measures the sweeps in ``plan.order`` and, within a sweep, by step and repeat; a time
    may run back behind the cycle before it by a jitter of up to :data:`CLOCK_JITTER_S`
    (cycles logged out of order), and the times must advance over the session. Reversed,
    permuted or frozen times would move the fitted speed of sound, and with it the
    signature, without a word (issue 13: log times never change a signature silently).

    Raises
    ------
    ArmsigError
        One line naming the first cycle that runs back too far, or the frozen clock.
    """
    rank = {sweep_id(s): k for k, s in enumerate(order)}
    sweep = _column(ranges, "sweep").astype(np.int64)
    step = _column(ranges, "step").astype(np.int64)
    repeat = _column(ranges, "repeat").astype(np.int64)
    t = _column(ranges, "t_s").astype(float)
    ids, at = np.unique(sweep, return_inverse=True)  # one lookup per sweep, not per echo
    where = np.array([rank.get(int(s), len(rank)) for s in ids], np.int64)[at.reshape(-1)]
    key = np.stack([where, step, repeat], axis=1)
    cycles, first = np.unique(key, axis=0, return_index=True)  # sorted along the order
    tc = t[first]
    latest = np.maximum.accumulate(tc)
    back = np.concatenate([[0.0], latest[:-1] - tc[1:]])  # how far each runs back
    expected = (
        f"cycle times along plan.order, then step, then repeat, running back by at most "
        f"{CLOCK_JITTER_S:g} s (the range-level refinement models the speed of sound in time)"
    )
    fix = (
        "record the rig's measurement times (MCAP publish_time, schemas/README.md), or "
        "--param refine.level=points"
    )
    if (back > CLOCK_JITTER_S).any():
        k = int(np.argmax(back > CLOCK_JITTER_S))
        s = int(sweep[first[k]])
        raise ArmsigError(
            "the /sonic/ranges times do not follow the measurement order: cycle "
            f"(sweep {sweep_name(s)}, step {cycles[k, 1]}, repeat {cycles[k, 2]}) is stamped "
            f"at {tc[k]:.3f} s, {back[k]:.3f} s before a cycle measured before it "
            f"({latest[k - 1]:.3f} s)",
            expected=expected,
            fix=fix,
        )
    if len(tc) > 1 and not tc[-1] - tc[0] > CLOCK_JITTER_S:
        raise ArmsigError(
            f"the /sonic/ranges times do not advance: {len(tc)} cycles within "
            f"{tc[-1] - tc[0]:.3f} s from the first measured to the last",
            expected=expected,
            fix=fix,
        )
