"""Read a session recording (MCAP) into plain arrays, with clear errors.

This is the pipeline's only door to the recording; it knows the channel
contract of ``schemas/mcap/`` and nothing of the simulator. On top of the file's
integrity and each message's schema (:mod:`pipeline.contract.mcap_read`) it checks
what one message cannot: the recorded rig layout, the robot description, that every
key names a planned sweep, values within the recorded limits, and that joint states
and measurements (digitize cycles of a sonic session, points of a point-sensor
session: :mod:`pipeline.stages.recording_points`) pair up by their keys. Tables come
out sorted by their keys, so the order and the log times of the messages never change
a result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.contract.blocks import BLOCK_TOPIC
from pipeline.contract.channels import (
    IMAGE_SET_CHANNELS,
    OPTIONAL_CHANNELS,
    POINT_BLOCK_CHANNELS,
    SENSOR_CHANNELS,
    SOURCE_METADATA,
)
from pipeline.contract.digest import file_sha256
from pipeline.errors import ArmsigError, RecordingError
from pipeline.stages.recording_keys import (
    KEY_FIX,
    key_text,
    message_keys,
    pair_keys,
    refuse_duplicates,
    refuse_step_gaps,
    seconds_after,
)
from pipeline.sweeps import CHECK_SWEEP, POSES_SWEEP, TOOL_SWEEP, sweep_id, sweep_name

__all__ = ["CHECK_SWEEP", "POSES_SWEEP", "TOOL_SWEEP", "Recording", "read_recording", "sweep_name"]

#: The stage list of a session of flange poses without joints (issue 40)
FLANGE_KIND = "camera-flange"
#: every channel a session recording may hold (sonic and point sensors)
_ALL = (*SENSOR_CHANNELS.values(), IMAGE_SET_CHANNELS, POINT_BLOCK_CHANNELS)  # issues 40, 45
TOPICS = tuple(dict.fromkeys(t for ch in _ALL for t in ch))
_KNOWN = {t: s for ch in _ALL for t, s in ch.items()}
#: Recorded joint values may pass the robot's limits by this much (deg or cm): far
#: above a servo's settling error (a few encoder counts) and an encoder offset
#: (tenths of a degree), far below what garbage or a wrong unit gives.
LIMIT_MARGIN = 5.0
_FIX = "re-copy the file from the rig, or re-record the session"
#: The channels whose rows a point session's /points/block messages may carry instead.
BLOCK_REPLACES = ("/robot/joint_state", "/points")


@dataclass(frozen=True)
class Recording:
    """Everything a session recording holds.

    ``sensor`` is the recorded sensor kind: ``sonic`` (the sparker digitizer: digitize
    cycles of slant ranges) or ``points`` (a point sensor: 3-D target positions). The
    arrays of the other kind are empty (zero rows).

    ``joint_*`` arrays have one row per commanded configuration, sorted by
    ``(sweep, step)``; ``cycle_*`` (sonic) one row per digitize cycle, sorted by
    ``(sweep, step, repeat)``; ``point_*`` (points) one row per measured target, sorted
    by ``(sweep, step, target)``. ``sweep`` is the target number (the swept joint),
    :data:`TOOL_SWEEP` for the tool measurement, :data:`CHECK_SWEEP` for the
    validation configurations or :data:`POSES_SWEEP` for a pose set. Times are seconds
    after the earliest joint state.
    """

    path: Path
    sha256: str
    rig: dict[str, Any]
    robot: dict[str, Any]
    sensor: str  # "sonic" | "points" | "camera"
    joint_sweep: np.ndarray  # (K,) int
    joint_step: np.ndarray  # (K,) int
    joint_t_s: np.ndarray  # (K,)
    q_commanded: np.ndarray  # (K, n) deg / cm
    q_encoder: np.ndarray  # (K, n) deg / cm
    joint_payload_kg: np.ndarray  # (K,) kg on the flange, NaN = not recorded
    joint_source_file: np.ndarray  # (K,) str: the imported row's file, "" = not recorded
    joint_source_line: np.ndarray  # (K,) int: its line there, 0 = not recorded
    joint_drift_cm: np.ndarray  # (K, 2) fixed targets' drift before / after, NaN = none
    cycle_sweep: np.ndarray  # (M,) int
    cycle_step: np.ndarray  # (M,) int
    cycle_repeat: np.ndarray  # (M,) int
    cycle_t_s: np.ndarray  # (M,)
    ranges_cm: np.ndarray  # (M, 5, 4), NaN = no echo
    point_sweep: np.ndarray  # (P,) int
    point_step: np.ndarray  # (P,) int
    point_target: np.ndarray  # (P,) str (target id)
    point_t_s: np.ndarray  # (P,)
    points_cm: np.ndarray  # (P, 3) sensor frame
    point_sigma_cm: np.ndarray  # (P,) isotropic std per coordinate, NaN = not recorded
    point_cov_cm2: np.ndarray  # (P, 3, 3) covariance, NaN = not recorded
    point_wxyz: np.ndarray  # (P, 4) unit quaternion of a 6-D target, NaN = not recorded
    point_orientation_sigma_deg: np.ndarray  # (P,) its σ per rotation-vector component, NaN = none
    # camera (issue 39): one row per detected target point, sorted by (sweep, step, point)
    detection_sweep: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    detection_step: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    detection_point: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    detection_uv_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    detection_sigma_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # a session of flange poses, no joints (issue 40): one row per image, sorted by key
    flange_sweep: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    flange_step: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    flange_in_base_cm: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    # the images referenced by content hash (/camera/images), one row per image
    image_sweep: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    image_step: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    image_file: np.ndarray = field(default_factory=lambda: np.zeros(0, str))
    image_sha256: np.ndarray = field(default_factory=lambda: np.zeros(0, str))
    image_dropped: np.ndarray = field(default_factory=lambda: np.zeros(0, str))

    @property
    def kind(self) -> str:
        """The stage list's key (:data:`pipeline.stages.catalog.SENSOR_STAGE_MODULES`): the
        sensor, or ``camera-flange`` for flange poses without joints."""
        return FLANGE_KIND if len(self.flange_step) else self.sensor


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
    from pipeline.contract.mcap_read import read_mcap  # parsing: only when not cached
    from pipeline.stages import recording_blocks, recording_points

    content = read_mcap(p, _KNOWN, _FIX)
    msgs = content.messages
    one_file = content.metadata.get(SOURCE_METADATA, {}).get("file", "")  # an import's
    rigs = msgs["/rig/description"]
    sensor = str(rigs[0][1].get("sensor", "sonic")) if len(rigs) == 1 else "sonic"
    if msgs["/robot/flange_pose"]:  # an image set without joint readings (issue 40)
        return _flange_recording(p, sha, msgs, sensor)
    topics = tuple(SENSOR_CHANNELS[sensor])
    in_blocks = BLOCK_REPLACES if msgs[BLOCK_TOPIC] else ()  # rows as columns (issue 45)
    missing = [t for t in topics if not msgs[t] and t not in in_blocks]
    if missing:
        raise RecordingError(
            f"{p}: missing channel(s) {', '.join(missing)}",
            expected="channels " + ", ".join(topics),
            fix="record every channel of schemas/mcap/ (see schemas/README.md)",
        )
    allowed = (*topics, *OPTIONAL_CHANNELS.get(sensor, ()))  # image references (issue 40)
    foreign = [t for t in TOPICS if t not in allowed and msgs[t]]
    if foreign:
        raise RecordingError(
            f"{p}: channel {foreign[0]} in a recording of sensor {sensor!r}",
            expected="channels " + ", ".join(topics) + " (/rig/description sensor)",
            got=f"{len(msgs[foreign[0]])} {foreign[0]} messages",
            fix="record the measurement channel of the declared sensor (schemas/README.md)",
        )
    rig = _single(p, msgs, "/rig/description")
    robot = _single(p, msgs, "/robot/description")
    desc, units = _check_rig_and_robot(p, rig, robot, sensor)
    n_points, n_avg = _planned(p, robot, len(units), sensor)

    b_joints, b_points = recording_blocks.block_rows(p, msgs[BLOCK_TOPIC], n_points, units,
                                                     one_file)  # fmt: skip
    joints, t_ns = _joint_arrays(p, msgs["/robot/joint_state"], b_joints, n_points, units, desc,
                                 one_file)  # fmt: skip
    t0 = int(t_ns.min())
    joints["joint_t_s"] = seconds_after(t_ns, t0)
    j_sweep, j_step = joints["joint_sweep"], joints["joint_step"]
    if sensor == "camera":
        from pipeline.stages import recording_camera, recording_flange

        _, target = recording_camera.check_camera_rig(p, rig)
        det = recording_camera.read_detections(p, msgs["/camera/detections"], target, n_points)
        ds, dk = det["detection_sweep"], det["detection_step"]
        pair_keys(
            p, j_sweep, j_step, ds, dk, lambda k: key_text(ds[k], dk[k]),
            "/camera/detections", "image",
        )  # fmt: skip
        images = recording_flange.image_arrays(p, msgs)  # rendered or imported (issue 40)
        ik = images["image_step"][images["image_dropped"] == ""]
        iw = images["image_sweep"][images["image_dropped"] == ""]
        if len(images["image_step"]):  # every joint state has its kept image
            pair_keys(p, j_sweep, j_step, iw, ik, lambda k: key_text(iw[k], ik[k]),
                      "/camera/images", "kept image")  # fmt: skip
        return Recording(p, sha, rig, robot, sensor, **joints, **_no_cycles(),
                         **recording_points.no_points(), **det, **images)  # fmt: skip
    if sensor == "points":
        measured = recording_points.read_points(
            p, msgs["/points"], robot["plan"], n_points, t0, b_points
        )
        ps, pk, pt = measured["point_sweep"], measured["point_step"], measured["point_target"]
        pair_keys(
            p, j_sweep, j_step, ps, pk,
            lambda k: key_text(ps[k], pk[k], target=pt[k]),
            "/points", "point",
        )  # fmt: skip
        return Recording(p, sha, rig, robot, sensor, **joints, **_no_cycles(), **measured)
    cycles = _sonic_arrays(p, msgs["/sonic/ranges"], n_points, n_avg, rig, t0)
    c_sweep, c_step, c_rep = cycles["cycle_sweep"], cycles["cycle_step"], cycles["cycle_repeat"]
    pair_keys(
        p, j_sweep, j_step, c_sweep, c_step,
        lambda k: key_text(c_sweep[k], c_step[k], c_rep[k]),
        "/sonic/ranges", "cycle",
    )  # fmt: skip
    return Recording(p, sha, rig, robot, sensor, **joints, **cycles, **recording_points.no_points())


def _flange_recording(
    p: Path, sha: str, msgs: dict[str, list[tuple[int, dict[str, Any]]]], sensor: str
) -> Recording:
    """A recording of flange poses and no joints (:mod:`pipeline.stages.recording_flange`)."""
    from pipeline.stages import recording_flange, recording_points

    foreign = [t for t in TOPICS if t not in IMAGE_SET_CHANNELS and msgs[t]]
    if sensor != "camera" or foreign:
        raise RecordingError(
            f"{p}: /robot/flange_pose in a recording of sensor {sensor!r} with "
            f"{', '.join(foreign) or 'no other channel'}",
            expected="channels " + ", ".join(IMAGE_SET_CHANNELS) + " (sensor 'camera')",
            fix="import the image set again (`pipeline import --format images`)",
        )
    rig = _single(p, msgs, "/rig/description")
    none, n0 = np.zeros(0, np.int64), np.zeros((0, 0))
    joints = {"joint_sweep": none, "joint_step": none, "joint_t_s": np.zeros(0),
              "q_commanded": n0, "q_encoder": n0, "joint_payload_kg": np.zeros(0),
              "joint_source_file": np.zeros(0, str), "joint_source_line": none,
              "joint_drift_cm": np.zeros((0, 2))}  # fmt: skip
    return Recording(p, sha, rig, {}, sensor, **joints, **_no_cycles(),
                     **recording_points.no_points(),
                     **recording_flange.flange_arrays(p, msgs))  # fmt: skip


def _no_cycles() -> dict[str, np.ndarray]:
    """The sonic arrays of a point-sensor recording: zero rows."""
    none = np.zeros(0, np.int64)
    return {
        "cycle_sweep": none,
        "cycle_step": none,
        "cycle_repeat": none,
        "cycle_t_s": np.zeros(0),
        "ranges_cm": np.zeros((0, 5, 4)),
    }


def _sonic_arrays(
    p: Path,
    rg: list[tuple[int, dict[str, Any]]],
    n_points: dict[int, int | None],
    n_avg: int,
    rig: dict[str, Any],
    t0: int,
) -> dict[str, np.ndarray]:
    """The ``cycle_*`` and ``ranges_cm`` arrays of the /sonic/ranges messages ``rg``,
    sorted by key, each key naming a planned position."""
    c_sweep, c_step = message_keys(p, "/sonic/ranges", [m for _, m in rg], n_points)
    c_rep = np.array([m["repeat"] for _, m in rg], np.int64)
    order = np.lexsort((c_rep, c_step, c_sweep))
    rg = [rg[k] for k in order]
    c_sweep, c_step, c_rep = c_sweep[order], c_step[order], c_rep[order]
    refuse_duplicates(p, "/sonic/ranges", c_sweep, c_step, c_rep)
    over = np.flatnonzero(c_rep >= n_avg)
    if len(over):
        k = over[0]
        raise RecordingError(
            f"{p}: /sonic/ranges cycle {key_text(c_sweep[k], c_step[k], c_rep[k])} is beyond "
            "the plan",
            expected=f"repeat 0 to {n_avg - 1} (plan.n_avg = {n_avg})",
            got=f"repeat {c_rep[k]}",
            fix=KEY_FIX,
        )
    return {
        "cycle_sweep": c_sweep,
        "cycle_step": c_step,
        "cycle_repeat": c_rep,
        "cycle_t_s": np.array([(t - t0) * 1e-9 for t, _ in rg]),
        "ranges_cm": _ranges(p, rg, c_sweep, c_step, c_rep, rig),
    }


def _single(p: Path, msgs: dict[str, list[tuple[int, dict[str, Any]]]], topic: str) -> Any:
    if len(msgs[topic]) != 1:
        raise RecordingError(
            f"{p}: {len(msgs[topic])} {topic} messages",
            expected="exactly one (the rig and robot are described once per session)",
            fix="record the description once",
        )
    return msgs[topic][0][1]


def _check_rig_and_robot(
    p: Path, rig: dict[str, Any], robot: dict[str, Any], sensor: str
) -> tuple[Any, list[str]]:
    """Refuse an unusable rig layout (sonic: the digitizer's geometry; a point sensor's
    description is all in its schema) or robot description; the description, units."""
    from pipeline.robots.description import description_from_dict
    from pipeline.sensor.geometry import DigitizerGeometry, check_geometry

    try:
        if sensor == "sonic":
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


def _planned(
    p: Path, robot: dict[str, Any], n: int, sensor: str
) -> tuple[dict[int, int | None], int]:
    """Sweep id -> planned positions (None: the tool, any number; plan.check and
    plan.poses n_points for :data:`CHECK_SWEEP` and :data:`POSES_SWEEP`), and plan.n_avg.

    A point-sensor session may hold a pose set (``plan.poses``) besides or instead of the
    joint sweeps; the tool measurement is then planned only when ``plan.order`` lists it.
    Every other session plans the tool measurement and at least one joint sweep."""
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
    if "poses" in plan and sensor not in ("points", "camera"):
        raise RecordingError(
            f"{p}: /robot/description plan.poses in a recording of sensor {sensor!r}",
            expected="a pose set in a point-sensor session (/rig/description sensor 'points')",
            fix="record the pose set with a point sensor, or drop plan.poses",
        )
    if "poses" in plan:
        points[POSES_SWEEP] = int(plan["poses"]["n_points"])
    if "poses" not in plan or "tool" in plan["order"]:
        points[TOOL_SWEEP] = None
    if not any(s > 0 for s in points) and POSES_SWEEP not in points:
        raise RecordingError(
            f"{p}: /robot/description plan measures no joint sweep and no pose set",
            expected="plan.sweeps with at least one sweep, or plan.poses",
            fix="repair the recorded plan",
        )
    if "check" in plan:
        points[CHECK_SWEEP] = int(plan["check"]["n_points"])
    order = [sweep_id(o) for o in plan["order"]]
    if sorted(order) != sorted(points):
        raise RecordingError(
            f"{p}: /robot/description plan.order does not list each sweep once",
            expected=", ".join(sweep_name(s) for s in sorted(points)),
            got=str(plan["order"]),
            fix="repair the recorded plan",
        )
    return points, int(plan["n_avg"])


def _joint_arrays(
    p: Path,
    js: list[tuple[int, dict[str, Any]]],
    blocks: dict[str, np.ndarray] | None,
    n_points: dict[int, int | None],
    units: list[str],
    desc: Any,  # RobotDescription
    one_file: str,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The ``joint_*`` arrays of the joint-state messages ``js`` and the rows of the
    blocks (:mod:`pipeline.stages.recording_blocks`, None: none), sorted by key, and
    their times (ns, uint64): each key planned and recorded once, no step gap, the
    readings fitting the robot's units and within its joint limits (through its coupling
    when it has one)."""
    from pipeline.stages.recording_blocks import merged

    n = len(units)
    payloads = [m for _, m in js]
    sweep, step = message_keys(p, "/robot/joint_state", payloads, n_points)
    fits = [
        m["units"] == units and len(m["q_commanded"]) == n and len(m["q_encoder"]) == n
        for m in payloads
    ]
    none = [math.nan] * n  # a message that does not fit: refused once sorted

    def q(name: str) -> np.ndarray:
        return np.array([m[name] if f else none for m, f in zip(payloads, fits, strict=True)],
                        float).reshape(-1, n)  # fmt: skip

    cols = {
        "joint_sweep": sweep,
        "joint_step": step,
        "t_ns": np.array([t for t, _ in js], np.uint64),
        "q_commanded": q("q_commanded"),
        "q_encoder": q("q_encoder"),
        "joint_payload_kg": np.array([m.get("payload_kg", np.nan) for m in payloads], float),
        "joint_source_file": np.array([m.get("source_file", one_file) for m in payloads], str),
        "joint_source_line": np.array([m.get("source_line", 0) for m in payloads], np.int64),
        "joint_drift_cm": np.array(
            [
                [m.get("tracker_drift_cm", np.nan), m.get("tracker_residual_cm", np.nan)]
                for m in payloads
            ],
            float,
        ).reshape(-1, 2),  # fmt: skip
    }
    message = np.arange(len(js))
    if blocks is not None:
        cols = merged([cols, blocks]) if len(js) else blocks
        message = np.r_[message, np.full(len(blocks["joint_step"]), -1)]
    order = np.lexsort((cols["joint_step"], cols["joint_sweep"]))
    if not (order == np.arange(len(order))).all():  # blocks are written in key order
        cols = {k: v[order] for k, v in cols.items()}
        message = message[order]
    sweep, step = cols["joint_sweep"], cols["joint_step"]
    refuse_duplicates(p, "/robot/joint_state", sweep, step)
    refuse_step_gaps(p, sweep, step)
    for k in np.flatnonzero(message >= 0):
        m = payloads[message[k]]
        if not fits[message[k]]:
            raise RecordingError(
                f"{p}: /robot/joint_state {key_text(sweep[k], step[k])} does not fit the robot",
                expected=f"{n} joint values in units {units}",
                got=f"units {m['units']}, {len(m['q_commanded'])} commanded, "
                f"{len(m['q_encoder'])} encoder values",
                fix="record one value per joint of /robot/description, deg or cm by joint type",
            )
    limits = desc.limits
    lo, hi = limits[:, 0] - LIMIT_MARGIN, limits[:, 1] + LIMIT_MARGIN
    for name in ("q_encoder", "q_commanded"):
        q_joint = desc.joints_from_readings(cols[name])
        bad = np.argwhere(~((q_joint >= lo) & (q_joint <= hi)))
        if len(bad):
            k, j = bad[0]
            raise RecordingError(
                f"{p}: /robot/joint_state {key_text(sweep[k], step[k])} {name} of joint {j + 1} "
                "is outside its limits" + (" (through the coupling)" if desc.coupling else ""),
                expected=f"{limits[j, 0]:g} to {limits[j, 1]:g} {units[j]} "
                f"(± {LIMIT_MARGIN:g} {units[j]})",
                got=f"{q_joint[k, j]:g} {units[j]}",
                fix="check the encoder units and the limits of /robot/description",
            )
    t_ns = cols.pop("t_ns")
    return cols, t_ns


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
            f"{p}: /sonic/ranges cycle {key_text(sweep[k], step[k], repeat[k])} reports a range "
            f"of sparker {s + 1} to microphone {'ABCD'[m]} outside the digitizer's window",
            expected=f"{lo:g} to {hi:g} cm (range_min_cm, range_max_cm), or null for no echo",
            got=f"{ranges[k, s, m]:g} cm",
            fix="record ranges the digitizer reported; a missing echo is null",
        )
    return ranges
