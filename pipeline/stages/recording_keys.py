"""Message keys of a session recording: their checks and their pairing (the sweep ids
themselves: :mod:`pipeline.sweeps`).

Shared by the sonic reader (:mod:`pipeline.stages.recording`) and the point reader
(:mod:`pipeline.stages.recording_points`). Every refusal names the key.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import RecordingError
from pipeline.sweeps import sweep_id, sweep_name

KEY_FIX = "repair the rig's writer: keys are documented in schemas/mcap/ (docs/rig.md)"


def key_text(sweep: Any, step: Any, repeat: Any = None, target: Any = None) -> str:
    """``(sweep 3, step 4)``, with ``, repeat r`` or ``, target T`` when given."""
    out = f"(sweep {sweep_name(sweep)}, step {int(step)}"
    if target is not None:
        out += f", target {target}"
    return out + (")" if repeat is None else f", repeat {int(repeat)})")


def seconds_after(t_ns: np.ndarray, t0: int) -> np.ndarray:
    """``(t - t0) * 1e-9`` of times ``t_ns`` (uint64 ns), the same doubles as Python's
    ``(t - t0) * 1e-9`` of ints (each difference rounded once to a float, then scaled)."""
    t = np.asarray(t_ns, np.uint64)
    base = np.uint64(t0)
    after = t >= base
    out = np.where(after, t - np.where(after, base, t), 0).astype(float)
    out[~after] = -(base - t[~after]).astype(float)
    return out * 1e-9


def message_keys(
    p: Path, topic: str, payloads: list[dict[str, Any]], n_points: dict[int, int | None]
) -> tuple[np.ndarray, np.ndarray]:
    """(sweep, step) of each message, each naming a planned position
    (``n_points``: sweep id -> planned positions, None: any number)."""
    sweep = np.array([sweep_id(m["sweep"]) for m in payloads], np.int64)
    step = np.array([m["step"] for m in payloads], np.int64)
    limit = np.array([n_points.get(int(s), _UNPLANNED) for s in sweep], dtype=object)
    limit = np.where(limit == None, _UNLIMITED, limit).astype(np.int64)  # noqa: E711 (tool)
    refuse_unplanned(p, topic, sweep, step, limit, lambda k: payloads[k]["sweep"], n_points)
    return sweep, step


_UNPLANNED, _UNLIMITED = -1, np.iinfo(np.int64).max


def planned_limit(n_points: dict[int, int | None], sweep: int) -> int:
    """The steps sweep ``sweep`` may have: its planned positions, the int64 maximum for
    the tool (any number), -1 when the plan has no such sweep."""
    limit = n_points.get(sweep, _UNPLANNED)
    return _UNLIMITED if limit is None else limit


def refuse_unplanned(
    p: Path,
    topic: str,
    sweep: np.ndarray,
    step: np.ndarray,
    limit: np.ndarray | int,
    recorded: Callable[[int], Any],
    n_points: dict[int, int | None],
) -> None:
    """Refuse the first key whose sweep is not planned (``limit`` -1) or whose step is not
    below its ``limit``; ``recorded(k)``: the k-th key's sweep as recorded."""
    bad = np.flatnonzero((limit == _UNPLANNED) | (step >= limit))
    if len(bad):
        k = bad[0]
        planned = [sweep_name(s) for s in sorted(n_points)]
        raise RecordingError(
            f"{p}: {topic} {key_text(sweep[k], step[k])} names no planned position",
            expected=f"a sweep of plan.order ({', '.join(planned)}) and a step below its "
            "plan.sweeps n_points",
            got=f"sweep {recorded(int(k))!r}, step {step[k]}",
            fix=KEY_FIX,
        )


def refuse_duplicates(
    p: Path, topic: str, *keys: np.ndarray, target: np.ndarray | None = None
) -> None:
    """``keys`` (and ``target``) sorted; refuse two messages with the same key."""
    same = np.ones(len(keys[0]) - 1, bool) if len(keys[0]) else np.zeros(0, bool)
    for k in (*keys, *(() if target is None else (target,))):
        same &= k[1:] == k[:-1]
    dup = np.flatnonzero(same)
    if len(dup):
        k = dup[0]
        sweep, step, *repeat = (a[k] for a in keys)
        text = key_text(
            sweep, step, repeat[0] if repeat else None, None if target is None else target[k]
        )
        raise RecordingError(
            f"{p}: {topic} key {text} is recorded twice",
            expected="one message per key",
            fix=KEY_FIX,
        )


def refuse_step_gaps(p: Path, sweep: np.ndarray, step: np.ndarray) -> None:
    """Steps of each sweep (sorted) must be 0, 1, ..., K-1."""
    first = np.r_[True, sweep[1:] != sweep[:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(len(sweep)), 0))
    gap = np.flatnonzero(step != np.arange(len(sweep)) - start)
    if len(gap):
        k = gap[0]
        want = k - start[k]
        raise RecordingError(
            f"{p}: /robot/joint_state sweep {sweep_name(sweep[k])} has no step {want}",
            expected="steps 0, 1, ... of every sweep without a gap",
            got=f"step {step[k]} after step {want - 1}" if want else f"first step {step[k]}",
            fix=KEY_FIX,
        )


def pair_keys(
    p: Path,
    j_sweep: np.ndarray,
    j_step: np.ndarray,
    m_sweep: np.ndarray,
    m_step: np.ndarray,
    m_key: Callable[[int], str],
    topic: str,
    what: str,
) -> None:
    """Every measurement (``what`` of ``topic``; ``m_key(k)`` spells the key of the k-th)
    has its joint state and every joint state at least one measurement."""
    stride = np.int64(1) << 21  # steps are at most 1e6 (schema) < 2**21
    j_key = j_sweep * stride + j_step  # sorted, unique
    c_key = m_sweep * stride + m_step
    orphan = np.flatnonzero(~np.isin(c_key, j_key))
    if len(orphan):
        raise RecordingError(
            f"{p}: {topic} {what} {m_key(int(orphan[0]))} has no /robot/joint_state",
            expected="the joint state of every measured configuration, same (sweep, step)",
            fix=KEY_FIX,
        )
    lonely = np.flatnonzero(~np.isin(j_key, c_key))
    if len(lonely):
        k = lonely[0]
        raise RecordingError(
            f"{p}: /robot/joint_state {key_text(j_sweep[k], j_step[k])} has no {topic} {what}",
            expected=f"at least one {what} per configuration, same (sweep, step)",
            fix=KEY_FIX,
        )
