"""Read a session recording (MCAP) into plain arrays, with clear errors.

This is the pipeline's only door to the recording; it knows the channel
contract of ``schemas/mcap/`` and nothing of the simulator. On top of the file's
integrity and each message's schema (:mod:`pipeline.contract.mcap_read`) it checks
what one message cannot: the recorded rig layout, the robot description, that every
key names a planned sweep, values within the recorded limits, and that joint states
and digitize cycles pair up by their keys. Tables come out sorted by their keys,
so the order and the log times of the messages never change a result.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.contract.channels import CHANNELS
from pipeline.contract.mcap_read import read_mcap
from pipeline.errors import ArmsigError, RecordingError

TOPICS = tuple(CHANNELS)
TOOL_SWEEP = 0  # the tool-probe measurement's sweep id in tables ("tool" in the recording)
CHECK_SWEEP = -1  # validation configurations' sweep id in tables ("check" in the recording)
#: Recorded joint values may pass the robot's limits by this much (deg or cm): far
#: above a servo's settling error (a few encoder counts) and an encoder offset
#: (tenths of a degree), far below what garbage or a wrong unit gives.
LIMIT_MARGIN = 5.0
_FIX = "re-copy the file from the rig, or re-record the session"
_KEY_FIX = "repair the rig's writer: keys are documented in schemas/mcap/ (docs/rig.md)"


@dataclass(frozen=True)
class Recording:
    """Everything a session recording holds.

    ``joint_*`` arrays have one row per commanded configuration, sorted by
    ``(sweep, step)``; ``cycle_*`` one row per digitize cycle, sorted by
    ``(sweep, step, repeat)``; ``sweep`` is the target number, or 0 for the tool probe.
    Times are seconds after the earliest joint state.
    """

    path: Path
    sha256: str
    rig: dict[str, Any]
    robot: dict[str, Any]
    joint_sweep: np.ndarray  # (K,) int
    joint_step: np.ndarray  # (K,) int
    joint_t_s: np.ndarray  # (K,)
    q_commanded: np.ndarray  # (K, n) deg / cm
    q_encoder: np.ndarray  # (K, n) deg / cm
    cycle_sweep: np.ndarray  # (M,) int
    cycle_step: np.ndarray  # (M,) int
    cycle_repeat: np.ndarray  # (M,) int
    cycle_t_s: np.ndarray  # (M,)
    ranges_cm: np.ndarray  # (M, 5, 4), NaN = no echo


def file_sha256(path: Path) -> str:
    """Content hash of a file (hex)."""
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def sweep_name(sweep: int) -> str:
    """A sweep id as the recording spells it: the target number, or 'tool'."""
    return "tool" if sweep == TOOL_SWEEP else str(int(sweep))


def read_recording(path: str | Path, sha256: str | None = None) -> Recording:
    """Parse ``recording.mcap``; cached per (path, content hash) within a process.

    ``sha256`` is the file's content hash when the caller has already computed it.
    """
    p = Path(path)
    if not p.is_file():
        raise RecordingError(
            f"{p}: no recording",
            expected="a recording.mcap in the session folder",
            fix="record one, or simulate it with `pipeline simulate NAME`",
        )
    return _read_cached(p.resolve(), sha256 or file_sha256(p))


@lru_cache(maxsize=4)
def _read_cached(p: Path, sha: str) -> Recording:
    msgs = read_mcap(p, CHANNELS, _FIX).messages
    missing = [t for t in TOPICS if not msgs[t]]
    if missing:
        raise RecordingError(
            f"{p}: missing channel(s) {', '.join(missing)}",
            expected="channels " + ", ".join(TOPICS),
            fix="record every channel of schemas/mcap/ (see schemas/README.md)",
        )
    rig = _single(p, msgs, "/rig/description")
    robot = _single(p, msgs, "/robot/description")
    desc, units = _check_rig_and_robot(p, rig, robot)
    n_points, n_avg = _planned(p, robot, len(units))

    js = msgs["/robot/joint_state"]
    j_sweep, j_step = _keys(p, "/robot/joint_state", [m for _, m in js], n_points)
    order = np.lexsort((j_step, j_sweep))
    js = [js[k] for k in order]
    j_sweep, j_step = j_sweep[order], j_step[order]
    _refuse_duplicates(p, "/robot/joint_state", j_sweep, j_step)
    _refuse_step_gaps(p, j_sweep, j_step)
    q_cmd, q_enc = _joint_values(p, js, j_sweep, j_step, units, desc)

    rg = msgs["/sonic/ranges"]
    c_sweep, c_step = _keys(p, "/sonic/ranges", [m for _, m in rg], n_points)
    c_rep = np.array([m["repeat"] for _, m in rg], np.int64)
    order = np.lexsort((c_rep, c_step, c_sweep))
    rg = [rg[k] for k in order]
    c_sweep, c_step, c_rep = c_sweep[order], c_step[order], c_rep[order]
    _refuse_duplicates(p, "/sonic/ranges", c_sweep, c_step, c_rep)
    over = np.flatnonzero(c_rep >= n_avg)
    if len(over):
        k = over[0]
        raise RecordingError(
            f"{p}: /sonic/ranges cycle {_key(c_sweep[k], c_step[k], c_rep[k])} is beyond the plan",
            expected=f"repeat 0 to {n_avg - 1} (plan.n_avg = {n_avg})",
            got=f"repeat {c_rep[k]}",
            fix=_KEY_FIX,
        )
    ranges = _ranges(p, rg, c_sweep, c_step, c_rep, rig)
    _pair(p, j_sweep, j_step, c_sweep, c_step, c_rep)

    t0 = min(t for t, _ in js)
    return Recording(
        path=p,
        sha256=sha,
        rig=rig,
        robot=robot,
        joint_sweep=j_sweep,
        joint_step=j_step,
        joint_t_s=np.array([(t - t0) * 1e-9 for t, _ in js]),
        q_commanded=q_cmd,
        q_encoder=q_enc,
        cycle_sweep=c_sweep,
        cycle_step=c_step,
        cycle_repeat=c_rep,
        cycle_t_s=np.array([(t - t0) * 1e-9 for t, _ in rg]),
        ranges_cm=ranges,
    )


def _key(sweep: Any, step: Any, repeat: Any = None) -> str:
    out = f"(sweep {sweep_name(sweep)}, step {int(step)}"
    return out + (")" if repeat is None else f", repeat {int(repeat)})")


def _single(p: Path, msgs: dict[str, list[tuple[int, dict[str, Any]]]], topic: str) -> Any:
    if len(msgs[topic]) != 1:
        raise RecordingError(
            f"{p}: {len(msgs[topic])} {topic} messages",
            expected="exactly one (the rig and robot are described once per session)",
            fix="record the description once",
        )
    return msgs[topic][0][1]


def _check_rig_and_robot(
    p: Path, rig: dict[str, Any], robot: dict[str, Any]
) -> tuple[Any, list[str]]:
    """Refuse an unusable rig layout or robot description; the description and units."""
    from pipeline.robots.description import description_from_dict
    from pipeline.sensor.geometry import DigitizerGeometry, check_geometry

    try:
        check_geometry(DigitizerGeometry.from_dict(rig))
        desc = description_from_dict(robot["robot"], source="/robot/description")
    except ArmsigError as exc:
        raise RecordingError(f"{p}: {exc}") from exc
    except (KeyError, TypeError, ValueError) as exc:  # a description the checks missed
        raise RecordingError(
            f"{p}: /robot/description robot is malformed",
            got=f"{type(exc).__name__}: {exc}",
            fix="see schemas/robot_description.md",
        ) from exc
    units = ["cm" if j.type == "prismatic" else "deg" for j in desc.joints]
    if len(robot["signature_q"]) != len(units):
        raise RecordingError(
            f"{p}: /robot/description signature_q has the wrong length",
            expected=f"{len(units)} joint values",
            got=str(len(robot["signature_q"])),
        )
    return desc, units


def _planned(p: Path, robot: dict[str, Any], n: int) -> tuple[dict[int, int | None], int]:
    """Sweep id -> planned positions (None: the tool, any number), and plan.n_avg."""
    plan = robot["plan"]
    points: dict[int, int | None] = {}
    for s in plan["sweeps"]:
        if s["joint"] > n or s["joint"] in points:
            raise RecordingError(
                f"{p}: /robot/description plan has a bad sweep of joint {s['joint']}",
                expected=f"at most one sweep per joint 1 to {n}",
                fix="repair the recorded plan",
            )
        points[s["joint"]] = s["n_points"]
    points[TOOL_SWEEP] = None
    order = [TOOL_SWEEP if o == "tool" else o for o in plan["order"]]
    if sorted(order) != sorted(points):
        raise RecordingError(
            f"{p}: /robot/description plan.order does not list each sweep once",
            expected=", ".join(sweep_name(s) for s in sorted(points)),
            got=str(plan["order"]),
            fix="repair the recorded plan",
        )
    return points, int(plan["n_avg"])


def _keys(
    p: Path, topic: str, payloads: list[dict[str, Any]], n_points: dict[int, int | None]
) -> tuple[np.ndarray, np.ndarray]:
    """(sweep, step) of each message, each naming a planned position."""
    sweep = np.array([TOOL_SWEEP if m["sweep"] == "tool" else m["sweep"] for m in payloads])
    step = np.array([m["step"] for m in payloads], np.int64)
    unplanned, unlimited = -1, np.iinfo(np.int64).max
    limit = np.array([n_points.get(int(s), unplanned) for s in sweep], dtype=object)
    limit = np.where(limit == None, unlimited, limit).astype(np.int64)  # noqa: E711 (tool)
    bad = np.flatnonzero((limit == unplanned) | (step >= limit))
    if len(bad):
        k = bad[0]
        planned = sorted(sweep_name(s) for s in n_points)
        raise RecordingError(
            f"{p}: {topic} {_key(sweep[k], step[k])} names no planned position",
            expected=f"a sweep of plan.order ({', '.join(planned)}) and a step below its "
            "plan.sweeps n_points",
            got=f"sweep {payloads[k]['sweep']!r}, step {step[k]}",
            fix=_KEY_FIX,
        )
    return sweep.astype(np.int64), step


def _refuse_duplicates(p: Path, topic: str, *keys: np.ndarray) -> None:
    """``keys`` sorted; refuse two messages with the same key."""
    same = np.ones(len(keys[0]) - 1, bool)
    for k in keys:
        same &= k[1:] == k[:-1]
    dup = np.flatnonzero(same)
    if len(dup):
        k = dup[0]
        raise RecordingError(
            f"{p}: {topic} key {_key(*(a[k] for a in keys))} is recorded twice",
            expected="one message per key",
            fix=_KEY_FIX,
        )


def _refuse_step_gaps(p: Path, sweep: np.ndarray, step: np.ndarray) -> None:
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
            fix=_KEY_FIX,
        )


def _joint_values(
    p: Path,
    js: list[tuple[int, dict[str, Any]]],
    sweep: np.ndarray,
    step: np.ndarray,
    units: list[str],
    desc: Any,  # RobotDescription
) -> tuple[np.ndarray, np.ndarray]:
    """Commanded and encoder readings (K, n), checked against units and the joint limits
    (the joint values, through the robot's coupling when it has one)."""
    n = len(units)
    for k, (_, m) in enumerate(js):
        if m["units"] != units or len(m["q_commanded"]) != n or len(m["q_encoder"]) != n:
            raise RecordingError(
                f"{p}: /robot/joint_state {_key(sweep[k], step[k])} does not fit the robot",
                expected=f"{n} joint values in units {units}",
                got=f"units {m['units']}, {len(m['q_commanded'])} commanded, "
                f"{len(m['q_encoder'])} encoder values",
                fix="record one value per joint of /robot/description, deg or cm by joint type",
            )
    q_cmd = np.array([m["q_commanded"] for _, m in js], float).reshape(-1, n)
    q_enc = np.array([m["q_encoder"] for _, m in js], float).reshape(-1, n)
    limits = desc.limits
    lo, hi = limits[:, 0] - LIMIT_MARGIN, limits[:, 1] + LIMIT_MARGIN
    for name, q_read in (("q_encoder", q_enc), ("q_commanded", q_cmd)):
        q = desc.joints_from_readings(q_read)
        bad = np.argwhere(~((q >= lo) & (q <= hi)))
        if len(bad):
            k, j = bad[0]
            raise RecordingError(
                f"{p}: /robot/joint_state {_key(sweep[k], step[k])} {name} of joint {j + 1} "
                "is outside its limits" + (" (through the coupling)" if desc.coupling else ""),
                expected=f"{limits[j, 0]:g} to {limits[j, 1]:g} {units[j]} "
                f"(± {LIMIT_MARGIN:g} {units[j]})",
                got=f"{q[k, j]:g} {units[j]}",
                fix="check the encoder units and the limits of /robot/description",
            )
    return q_cmd, q_enc


def _ranges(
    p: Path,
    rg: list[tuple[int, dict[str, Any]]],
    sweep: np.ndarray,
    step: np.ndarray,
    repeat: np.ndarray,
    rig: dict[str, Any],
) -> np.ndarray:
    """Raw ranges (M, 5, 4), NaN = no echo; every range within the digitizer's window."""
    nan = math.nan
    flat = [
        nan if v is None else v for _, m in rg for row in m["ranges_cm"] for v in row
    ]  # the schema holds 5 x 4 numbers or nulls per message
    ranges = np.array(flat, float).reshape(-1, 5, 4)
    lo, hi = float(rig["range_min_cm"]), float(rig["range_max_cm"])
    bad = np.argwhere(~np.isnan(ranges) & ~((ranges >= lo) & (ranges <= hi)))
    if len(bad):
        k, s, m = bad[0]
        raise RecordingError(
            f"{p}: /sonic/ranges cycle {_key(sweep[k], step[k], repeat[k])} reports a range "
            f"of sparker {s + 1} to microphone {'ABCD'[m]} outside the digitizer's window",
            expected=f"{lo:g} to {hi:g} cm (range_min_cm, range_max_cm), or null for no echo",
            got=f"{ranges[k, s, m]:g} cm",
            fix="record ranges the digitizer reported; a missing echo is null",
        )
    return ranges


def _pair(
    p: Path,
    j_sweep: np.ndarray,
    j_step: np.ndarray,
    c_sweep: np.ndarray,
    c_step: np.ndarray,
    c_rep: np.ndarray,
) -> None:
    """Every cycle has its joint state and every joint state at least one cycle."""
    stride = np.int64(1) << 21  # steps are at most 1e6 (schema) < 2**21
    j_key = j_sweep * stride + j_step  # sorted, unique
    c_key = c_sweep * stride + c_step
    orphan = np.flatnonzero(~np.isin(c_key, j_key))
    if len(orphan):
        k = orphan[0]
        raise RecordingError(
            f"{p}: /sonic/ranges cycle {_key(c_sweep[k], c_step[k], c_rep[k])} has no "
            "/robot/joint_state",
            expected="the joint state of every measured configuration, same (sweep, step)",
            fix=_KEY_FIX,
        )
    lonely = np.flatnonzero(~np.isin(j_key, c_key))
    if len(lonely):
        k = lonely[0]
        raise RecordingError(
            f"{p}: /robot/joint_state {_key(j_sweep[k], j_step[k])} has no /sonic/ranges cycle",
            expected="at least one digitize cycle per configuration, same (sweep, step)",
            fix=_KEY_FIX,
        )
