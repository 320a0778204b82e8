"""Measured rows -> the messages of a point-session recording (schemas/mcap/).

Each joint's sweep becomes sweep ``j`` with its steps ordered by the joint's value (its
reading through the robot's coupling); the rows measured with every joint at home
(whole turns aside) become the tool measurement (sweep ``tool``, signature configuration
q^s = their mean reading); every other row that is in no sweep becomes a validation
configuration (sweep ``check``); a tool row a whole turn from home is recorded on home's
turn (the same pose, and q^s its reading). Every target of a row is recorded; the joint sweeps and
the tool measurement of a file measure the same targets, reflectors on the last link
(``plan.sweeps_measure_tool``; with several, ``plan.tool_targets``: each one point of the
last link in every sweep). A pose set's rows become
sweep ``poses`` in file order (``plan.poses``), with no tool measurement: q^s is the
first pose's readings. The readings are recorded as both commanded and encoder values:
a file holds only what the joints read. A point's stated σ is its ``sigma_cm`` (the
same for x, y, z) or a diagonal ``cov_cm2``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.contract.blocks import BLOCK_TOPIC, block_payload, noise_fields, rows_per_block
from pipeline.importers.rows import MeasuredRows
from pipeline.importers.sweeps import whole_turns
from pipeline.rig.recorder import Message
from pipeline.robots.description import RobotDescription, description_to_dict
from pipeline.stages.recording import CHECK_SWEEP, POSES_SWEEP

T0_NS = 1_767_225_600 * 10**9  # 2026-01-01T00:00:00Z: the recording carries no foreign time
STEP_NS = 10**9  # one configuration per second, in the order they are written


@dataclass(frozen=True)
class ToolChoice:
    """Rows of the tool measurement, their readings as recorded (on home's turn: a row a
    whole turn away from home is the same pose) and the signature configuration q^s
    (deg / cm)."""

    rows: np.ndarray  # (m,) row indices
    signature_q: np.ndarray  # (n,)
    note: str  # how they were chosen, for the user
    warning: str | None = None  # one line for the user when the choice is a fallback
    readings: np.ndarray | None = None  # (m, n); None: the rows' own readings


def tool_rows(
    rows: MeasuredRows, home: np.ndarray, robot: RobotDescription, tol: np.ndarray
) -> ToolChoice:
    """The rows where every joint is at home: its joint value within ``tol`` of home's,
    whole turns aside (a revolute joint 360 deg away is home); q^s = their mean reading,
    each row's readings taken to the turn of ``home`` first.

    When no row is at home, the row of the last joint's sweep nearest home is the
    tool measurement and q^s its readings (home except the last joint): its ``warning``
    says so (the command prints it as one line).
    A pose set has no tool measurement; q^s is the first pose's readings.
    """
    poses = np.flatnonzero(rows.sweep == POSES_SWEEP)
    if len(poses):
        note = f"the pose set (fitted), q^s the readings of {rows.short(poses[0], 0)}"
        return ToolChoice(np.zeros(0, np.int64), rows.q[poses[0]].copy(), note)
    d = robot.joints_from_readings(rows.q) - robot.joints_from_readings(home)
    turns = whole_turns(d, robot.prismatic)
    at_home = np.flatnonzero((np.abs(d - turns) <= tol).all(axis=1))
    if len(at_home):
        # the readings of the same joint values on home's turn (through the coupling)
        shift = robot.readings_from_joints(turns) - robot.readings_from_joints(0.0 * turns)
        q = rows.q[at_home] - shift[at_home]
        return ToolChoice(at_home, q.mean(axis=0), "rows with every joint at home", None, q)
    n = rows.q.shape[1]
    last = np.flatnonzero(rows.sweep == n)
    k = last[np.argmin(np.abs((d - turns)[last, -1]))]
    note = (
        f"no row has every joint at home; the tool is the point of {rows.short(k, 0)} "
        f"(joint {n} at {rows.q[k, -1]:g} instead of {home[-1]:g}), and q^s its readings"
    )
    return ToolChoice(np.array([k]), rows.q[k].copy(), note, f"{rows.name}: {note}")


def session_messages(
    rows: MeasuredRows,
    robot: RobotDescription,
    tool: ToolChoice,
    instrument: str,
    tool_local_cm: np.ndarray | None = None,
    robot_id: str | None = None,
    in_blocks: bool = True,
) -> list[Message]:
    """The recording's messages: descriptions, then joint states and points by (sweep,
    step); a pose set's in ``/points/block`` messages unless not ``in_blocks``.
    ``tool_local_cm``: the design tool point in the last D-H frame (cm), else the
    robot description's tool; ``robot_id``: the arm's own id, recorded when given."""
    units = [j.unit for j in robot.joints]
    ids = list(rows.targets)
    values = robot.joints_from_readings(rows.q)
    configs: list[tuple[str | int, int, int]] = []  # (sweep name, step, row)
    sweeps: list[dict[str, Any]] = []
    for j in range(1, robot.n_joints + 1):
        sel = np.flatnonzero(rows.sweep == j)
        if len(sel) == 0:
            continue  # a pose set: no joint sweep
        sel = sel[np.argsort(values[sel, j - 1], kind="stable")]
        configs += [(j, s, int(k)) for s, k in enumerate(sel)]
        sweeps.append(
            {
                "joint": j,
                "n_points": len(sel),
                "q_first": float(values[sel[0], j - 1]),
                "q_last": float(values[sel[-1], j - 1]),
                "targets": ids,
            }
        )
    configs += [("tool", s, int(k)) for s, k in enumerate(tool.rows)]
    poses = np.flatnonzero(rows.sweep == POSES_SWEEP)
    check = np.flatnonzero(rows.sweep == CHECK_SWEEP)
    blocks = in_blocks and len(poses) > 0  # a pose set's rows as columns (issue 45)
    if blocks:
        blocked = _blocks(rows, {"poses": poses, "check": check}, len(configs), units, ids)
    else:
        configs += [("poses", s, int(k)) for s, k in enumerate(poses)]
        configs += [("check", s, int(k)) for s, k in enumerate(check)]
    local = robot.tool.xyz_cm if tool_local_cm is None else tool_local_cm
    plan: dict[str, Any] = {
        "n_avg": 1,
        "order": [s["joint"] for s in sweeps]
        + (["tool"] if len(tool.rows) else [])
        + (["poses"] if len(poses) else [])
        + (["check"] if len(check) else []),
        "sweeps": sweeps,
        "tool_local_cm": [float(v) for v in local],
        "tool_target": ids[0],
    }
    if sweeps:
        plan["sweeps_measure_tool"] = True  # every row measured every target on the end link
        if len(ids) > 1:
            plan["tool_targets"] = ids  # each one point on the last link, in every sweep
    if len(poses):
        plan["poses"] = {"n_points": len(poses), "targets": ids}
    if len(check):
        plan["check"] = {"n_points": len(check)}
    messages = [
        Message("/rig/description", T0_NS, {"sensor": "points", "instrument": instrument}),
        Message(
            "/robot/description",
            T0_NS,
            {
                "robot": description_to_dict(robot),
                "signature_q": [float(v) for v in tool.signature_q],
                "plan": plan,
                "mode": "imported",
                **({"robot_id": robot_id} if robot_id is not None else {}),
            },
        ),
    ]
    tool_q = rows.q[tool.rows] if tool.readings is None else tool.readings
    several = len(set(rows.files)) > 1
    for c, (sweep, step, k) in enumerate(configs):
        t_ns = T0_NS + (c + 1) * STEP_NS
        q = [float(v) for v in (tool_q[step] if sweep == "tool" else rows.q[k])]
        state: dict[str, Any] = {
            "sweep": sweep, "step": step, "q_commanded": q, "q_encoder": q, "units": units
        }  # fmt: skip
        if rows.payload_kg is not None:
            state["payload_kg"] = float(rows.payload_kg[k])
        if rows.drift_cm is not None:  # fixed targets: the tracker's drift at this pose
            for key, v in (("tracker_drift_cm", rows.drift_cm[k]),
                           ("tracker_residual_cm", rows.residual_cm[k])):  # type: ignore[index]  # fmt: skip
                if np.isfinite(v):
                    state[key] = float(v)
        if several:  # one file: armsig.source names it, not every message (issue 42)
            state["source_file"] = rows.file_of(k)
        if rows.lines is not None and rows.lines[k] > 0:
            state["source_line"] = int(rows.lines[k])
        messages.append(Message("/robot/joint_state", t_ns, state))
        for t, target in enumerate(ids):
            x, y, z = (float(v) for v in rows.targets[target][k])
            point: dict[str, Any] = {
                "sweep": sweep, "step": step, "target": target, "x_cm": x, "y_cm": y, "z_cm": z
            }  # fmt: skip
            if rows.orientation_wxyz is not None and t == 0:
                point["orientation_wxyz"] = [float(v) for v in rows.orientation_wxyz[k]]
                if rows.orientation_sigma_deg is not None:
                    point["orientation_sigma_deg"] = float(rows.orientation_sigma_deg)
            if rows.sigma is not None:
                point.update(noise_fields(rows.sigma[target][k]))
            messages.append(Message("/points", t_ns, point))
    return messages + blocked if blocks else messages


def _blocks(
    rows: MeasuredRows, sweeps: dict[str, np.ndarray], c0: int, units: list[str], ids: list[str]
) -> list[Message]:
    """The ``/points/block`` messages of a pose set: per sweep (``poses``, ``check``) its
    rows in step order, :func:`~pipeline.contract.blocks.rows_per_block` a message, what
    the per-configuration messages would carry (:mod:`pipeline.contract.blocks`); the
    first is the ``c0``-th configuration of the recording."""
    names = list(dict.fromkeys(rows.files))
    files = None
    if len(names) > 1:  # one file: armsig.source names it, not every row (issue 42)
        number = {f: i for i, f in enumerate(names)}
        files = np.array([number[f] for f in rows.files], np.int32)
    out = []
    for sweep, index in sweeps.items():
        per = rows_per_block(_columns(rows, index[:1], ids, names, files)[0]) if len(index) else 1
        for start in range(0, len(index), per):
            cols, fields = _columns(rows, index[start : start + per], ids, names, files)
            payload = block_payload(sweep, start, units, ids, cols, **fields)
            out.append(Message(BLOCK_TOPIC, T0_NS + (c0 + start + 1) * STEP_NS, payload))
        c0 += len(index)
    return out


def _columns(
    rows: MeasuredRows, k: np.ndarray, ids: list[str], names: list[str], files: np.ndarray | None
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """A block's columns and fields of rows ``k``, in step order (its time as a
    per-configuration message's: one configuration a second)."""
    cols: dict[str, np.ndarray] = {
        "dt_ns": np.arange(len(k), dtype=np.int64) * STEP_NS,
        "q_commanded": rows.q[k],  # and the encoder's: a file holds what the joints read
        "points_cm": np.stack([rows.targets[t][k] for t in ids], axis=1),
    }
    fields: dict[str, Any] = {}
    if rows.sigma is not None:
        cols["sigma_cm"] = np.stack([rows.sigma[t][k] for t in ids], axis=1)
    if rows.orientation_wxyz is not None:
        cols["orientation_wxyz"] = rows.orientation_wxyz[k]
        if rows.orientation_sigma_deg is not None:
            fields["orientation_sigma_deg"] = float(rows.orientation_sigma_deg)
    if rows.payload_kg is not None:
        cols["payload_kg"] = rows.payload_kg[k]
    if rows.drift_cm is not None:  # fixed targets: the tracker's drift at each pose
        cols["tracker_drift_cm"] = rows.drift_cm[k]
        cols["tracker_residual_cm"] = rows.residual_cm[k]  # type: ignore[index]
    if files is not None:
        cols["source_file"] = files[k]
        fields["source_files"] = names
    if rows.lines is not None:
        cols["source_line"] = np.maximum(rows.lines[k], 0)
    return cols, fields
