"""Stage ``frames``: S-Model link frames S̄_0 … S̄_n from the features (4.48)-(4.50), and the tool.

``S̄_{i-1}`` comes from joint i's features: origin at the centre of rotation,
Z along the oriented plane normal, X toward the first target position projected
onto the plane (revolute); origin at the mean target position and Z along the
line of translation (prismatic, Figure 4-6). ``S̄_n = S̄_{n-1}``.

Signature readings: ``S̄_i`` (i < n) is measured while joint i holds still
during sweep i+1, so q̄_i^s is joint i's reading there (median over the sweep);
q̄_n^s is joint n's reading at the tool measurement, which also fixes the tool:
``tool = T_sig(q_tool)^{-1} · p_tool`` with the orientation of ``S_n``. A tool
measurement repeated as several steps of the ``tool`` sweep gives the mean of the
tools of its usable steps, each paired with its own joint state by (sweep, step).
When the joint sweeps measured the tool point too (``plan.sweeps_measure_tool``:
imports where every row measured the end effector) their points join the mean.

Common configuration: a held joint may read differently in different sweeps (the
arm parked between sweeps, the brake engaging: it re-settles by a count or two).
Sweep i's features are measured with joints 1 … i-1 at the readings recorded
during sweep i (median over the sweep), not at q̄^s. Each ``S̄_{i-1}`` is brought
to q̄^s with those readings and the frames already identified for joints
1 … i-1, in order from sweep 2 to n
(:func:`~pipeline.kinematics.signature.frames_at_signature`); exact on noiseless
data. When the readings equal q̄^s (no re-settling) the frames are unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.positions import positions, sweep_rows
from pipeline.stages.recording import POSES_SWEEP, TOOL_SWEEP, sweep_name
from pipeline.stages.session import session_plan, session_robot
from pipeline.units import joints_to_internal

if TYPE_CHECKING:
    from pipeline.kinematics.chain import SerialChain

MATRIX_COLUMNS = ("nx", "ny", "nz", "ox", "oy", "oz", "ax", "ay", "az", "px_cm", "py_cm", "pz_cm")


def matrices_to_columns(T: np.ndarray) -> dict[str, np.ndarray]:
    """(m, 4, 4) transforms -> the twelve (4.49)/(4.58) columns."""
    cols = {}
    for k, name in enumerate(MATRIX_COLUMNS):
        cols[name] = T[:, k % 3, k // 3]
    return cols


def matrices_from_columns(table: pa.Table) -> np.ndarray:
    """Inverse of :func:`matrices_to_columns`, shape (m, 4, 4)."""
    m = table.num_rows
    T = np.tile(np.eye(4), (m, 1, 1))
    for k, name in enumerate(MATRIX_COLUMNS):
        T[:, k % 3, k // 3] = table.column(name).to_numpy()
    return T


def joint_readings(joints: pa.Table, sweep: int, n: int, prismatic: np.ndarray) -> np.ndarray:
    """Encoder readings (K, n) of the configurations of one sweep, boundary units, by step."""
    return sweep_readings(joints, sweep, n, prismatic)[1]


def sweep_readings(
    joints: pa.Table, sweep: int, n: int, prismatic: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Steps (K,) and encoder readings (K, n) of one sweep's configurations, by step."""
    import pyarrow.compute as pc  # lazy: ~70 ms of import, which a warm run never needs

    sel = joints.filter(pc.equal(joints.column("sweep"), sweep))
    if sel.num_rows == 0:
        return np.zeros(0, np.int64), np.zeros((0, n))
    deg = sel.column("q_deg").to_numpy(zero_copy_only=False)
    cm = sel.column("q_cm").to_numpy(zero_copy_only=False)
    q = np.where(np.tile(prismatic, sel.num_rows // n), cm, deg).astype(float).reshape(-1, n)
    steps = sel.column("step").to_numpy()[::n].astype(np.int64)
    order = np.argsort(steps, kind="stable")
    return steps[order], q[order]


def readings_at(
    joints: pa.Table, sweep: int, steps: np.ndarray, n: int, prismatic: np.ndarray
) -> np.ndarray:
    """Encoder readings (len(steps), n) of sweep ``sweep`` at ``steps``, joined by key.

    Raises :class:`StageError` naming a (sweep, step) that has no joint state.
    """
    have, q = sweep_readings(joints, sweep, n, prismatic)
    at = np.searchsorted(have, steps)
    found = at < len(have)
    found[found] = have[at[found]] == steps[found]
    if not found.all():
        raise StageError(
            f"no joint state for (sweep {sweep_name(sweep)}, step {steps[~found][0]})",
            expected="a joint state for every measured configuration",
            fix="re-record the session; the recording is inconsistent",
        )
    return q[at]


def signature_readings(joints: pa.Table, prismatic: np.ndarray, source: str) -> np.ndarray:
    """q̄^s (n,) in boundary units, per the module docstring."""
    n = len(prismatic)
    qs = np.zeros(n)
    for i in range(1, n + 1):
        sweep = i + 1 if i < n else TOOL_SWEEP
        q = joint_readings(joints, sweep, n, prismatic)
        if len(q) == 0:
            what = f"sweep {sweep}" if sweep else "the tool measurement"
            raise StageError(
                f"{source}: no joint states for {what}",
                expected=f"every joint sweep 1..{n} and the tool measurement",
                fix="re-record the missing sweep",
            )
        qs[i - 1] = np.median(q[:, i - 1])
    return qs


def held_readings(joints: pa.Table, prismatic: np.ndarray) -> np.ndarray:
    """Readings (n, n) during every joint sweep, boundary units: row i-1 holds the
    median over sweep i's configurations of each joint's reading (module docstring)."""
    n = len(prismatic)
    out = np.zeros((n, n))
    for i in range(1, n + 1):
        q = joint_readings(joints, i, n, prismatic)
        if len(q) == 0:
            raise StageError(
                f"joints: no joint states for sweep {i}",
                expected=f"every joint sweep 1..{n} and the tool measurement",
                fix="re-record the missing sweep",
            )
        out[i - 1] = np.median(q, axis=0)
    return out


def tool_from_probe(chain: SerialChain, q_tool: np.ndarray, p_tool: np.ndarray) -> np.ndarray:
    """Tool of a signature chain from the probe measurement (module docstring).

    Parameters
    ----------
    chain : SerialChain
        Signature chain without tool, optionally with a batch of robots.
    q_tool : ndarray, shape (n,)
        Readings at the tool measurement (rad / cm).
    p_tool : ndarray, shape (..., 3)
        Measured probe position, sensor frame (cm).

    Returns
    -------
    tool : ndarray, shape (..., 4, 4)
        Translation only: the probe in the last S-Model frame, its orientation.
    """
    from pipeline.kinematics.chain import forward_kinematics

    flange = forward_kinematics(chain, q_tool)
    d = np.asarray(p_tool, float) - flange[..., :3, 3]
    tool = np.zeros((*d.shape[:-1], 4, 4))
    tool[..., :, :] = np.eye(4)
    tool[..., :3, 3] = (np.swapaxes(flange[..., :3, :3], -1, -2) @ d[..., None])[..., 0]
    return tool


def plan_tool_target(inputs: Mapping[str, Any]) -> str | None:
    """``plan.tool_target`` of the session (None: the tool sweep's only target is the tool)."""
    tool = session_plan(inputs["session"]).get("tool_target")
    return None if tool is None else str(tool)


def tool_points_of_sweeps(
    inputs: Mapping[str, Any], n: int, pris: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Readings (m, n) and positions (m, 3) of the tool point measured in the joint sweeps:
    the usable ``plan.tool_target`` rows when ``plan.sweeps_measure_tool`` (imports where
    every row measured the end effector, e.g. SScanSS-2's), else none. With them the tool
    is the mean of the tools of every measurement of the tool point: its least-squares
    position given the chain, not one measurement's."""
    plan = session_plan(inputs["session"])
    if not plan.get("sweeps_measure_tool", False):
        return np.zeros((0, n)), np.zeros((0, 3))
    parts = [usable_points(inputs, i, plan.get("tool_target"), n, pris) for i in range(1, n + 1)]
    return np.vstack([q for q, _ in parts]), np.vstack([p for _, p in parts])


def usable_points(
    inputs: Mapping[str, Any], sweep: int, target: str | None, n: int, pris: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Readings (K, n, boundary units) and positions (K, 3) of the usable measurements of
    ``target`` (every target when None) in ``sweep``, each joined to its joint state by
    (sweep, step)."""
    rows = sweep_rows(inputs["positions"], sweep, target)
    p = positions(rows)
    ok = ~np.isnan(p).any(axis=1)
    steps = rows.column("step").to_numpy().astype(np.int64)[ok]
    q = readings_at(inputs["joints"], sweep, steps, n, pris) if ok.any() else np.zeros((0, n))
    return q, p[ok]


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    from pipeline.kinematics.signature import (
        frame_from_features,
        frames_at_signature,
        signature_chain,
    )

    robot = session_robot(inputs["session"])
    n, pris = robot.n_joints, robot.prismatic
    feat = inputs["features"]
    if feat.num_rows != n and "poses" in session_plan(inputs["session"]):
        return _design_start_table(inputs, robot)
    if feat.num_rows != n:
        raise StageError(
            "features: not one row per joint", expected=f"{n} rows", got=str(feat.num_rows)
        )
    F = np.zeros((n + 1, 4, 4))
    for row in feat.to_pylist():
        i = row["joint"]
        axis = [row["axis_x"], row["axis_y"], row["axis_z"]]
        origin = [row["center_x_cm"], row["center_y_cm"], row["center_z_cm"]]
        toward = [row["first_x_cm"], row["first_y_cm"], row["first_z_cm"]]
        F[i - 1] = frame_from_features(axis, origin, toward)  # Eq. (4.49), (4.50)
    qs = signature_readings(inputs["joints"], pris, "joints")
    # Each sweep's frame from the readings recorded during it to q̄^s (module docstring).
    held = joints_to_internal(held_readings(inputs["joints"], pris), pris)
    F[:n] = frames_at_signature(F[:n], held, joints_to_internal(qs, pris), pris)
    F[n] = F[n - 1]  # S̄_n = S̄_{n-1}
    # The tool point: plan.tool_target (the tool sweep may measure more targets on the
    # last link, plan.tool_targets), else the tool sweep's only target.
    tool_rows = sweep_rows(inputs["positions"], TOOL_SWEEP, plan_tool_target(inputs))
    p_tool = positions(tool_rows)
    usable = ~np.isnan(p_tool).any(axis=1)
    if not usable.any():
        raise StageError(
            "no usable tool-probe measurement",
            expected="sweep 'tool' with at least one usable cycle",
            fix="re-record the tool measurement at the signature configuration",
        )
    steps = tool_rows.column("step").to_numpy().astype(np.int64)[usable]
    q_tool = readings_at(inputs["joints"], TOOL_SWEEP, steps, n, pris)
    q_more, p_more = tool_points_of_sweeps(inputs, n, pris)  # imports: the end effector
    q_tool, p_tool = np.vstack([q_tool, q_more]), np.vstack([p_tool[usable], p_more])
    usable = np.ones(len(p_tool), bool)
    chain = signature_chain(F, joints_to_internal(qs, pris), pris)
    # Every usable probe measurement (repeated steps of the tool sweep): the mean of
    # their tools, each from its own reading; one measurement gives exactly its tool.
    tools = np.stack(
        [
            tool_from_probe(chain, joints_to_internal(q, pris), p)
            for q, p in zip(q_tool, p_tool[usable], strict=True)
        ]
    )
    tool = tools.mean(axis=0) if len(tools) > 1 else tools[0]
    return frames_table(np.concatenate([F, tool[None]], axis=0), qs, pris)


def pose_tool_target(plan: Mapping[str, Any], pos: pa.Table) -> str:
    """The target id of the tool point in a session's pose set: ``plan.tool_target``, else
    the only target it measures (the recording reader refuses several without it)."""
    if "tool_target" in plan:
        return str(plan["tool_target"])
    ids = sorted(set(sweep_rows(pos, POSES_SWEEP).column("target").to_pylist()))
    return ids[0] if ids else ""


def tool_point_rows(
    inputs: Mapping[str, Any], n: int, pris: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Joint values (K, n, boundary units) and positions (K, 3) of every usable measurement
    of the tool point in the tool sweep and the pose set, each joined to its joint state by
    (sweep, step)."""
    plan = session_plan(inputs["session"])
    tool = usable_points(inputs, TOOL_SWEEP, plan_tool_target(inputs), n, pris)
    poses = usable_points(inputs, POSES_SWEEP, pose_tool_target(plan, inputs["positions"]), n, pris)
    return np.vstack([tool[0], poses[0]]), np.vstack([tool[1], poses[1]])


def _design_start_table(inputs: Mapping[str, Any], robot: Any) -> pa.Table:
    """The frames of a session identified from its pose set: the design model registered
    to the measured tool points (:func:`pipeline.refine.start.design_start`), at q̄^s the
    recorded signature configuration (the stage ``refine`` fits the chain from there)."""
    from pipeline.refine.start import design_start

    n, pris = robot.n_joints, robot.prismatic
    plan = session_plan(inputs["session"])
    q, p = tool_point_rows(inputs, n, pris)
    qs = robot.joints_from_readings(np.asarray(plan["signature_q"], float))
    start = design_start(
        robot.design_chain(),
        joints_to_internal(q, pris),
        p,
        np.asarray(plan["tool_local_cm"], float),
        joints_to_internal(qs, pris),
    )
    return frames_table(np.concatenate([start.frames, start.tool[None]], axis=0), qs, pris)


def frames_table(T: np.ndarray, qs: np.ndarray, pris: np.ndarray) -> pa.Table:
    """The ``frames`` table of ``S̄_0 … S̄_n`` and the tool ``T`` (n + 2, 4, 4) at q̄^s ``qs``
    (n,, boundary units)."""
    n = len(pris)
    q_deg = np.full(n + 2, np.nan)
    q_cm = np.full(n + 2, np.nan)
    q_deg[1 : n + 1] = np.where(pris, np.nan, qs)
    q_cm[1 : n + 1] = np.where(pris, qs, np.nan)
    return pa.table(
        {
            "frame": np.arange(n + 2, dtype=np.int32),
            "kind": ["link"] * (n + 1) + ["tool"],
            "from_joint": np.r_[np.arange(1, n + 1), 0, 0].astype(np.int32),
            **matrices_to_columns(T),
            "q_signature_deg": pa.array(q_deg, mask=np.isnan(q_deg)),
            "q_signature_cm": pa.array(q_cm, mask=np.isnan(q_cm)),
        }
    )


def chain_from_frames(frames: pa.Table, prismatic: np.ndarray):  # -> SerialChain
    """The signature chain (with tool) rebuilt from the ``frames`` table."""
    from pipeline.kinematics.signature import signature_chain

    T = matrices_from_columns(frames)
    n = len(prismatic)
    deg = frames.column("q_signature_deg").to_numpy(zero_copy_only=False)[1 : n + 1]
    cm = frames.column("q_signature_cm").to_numpy(zero_copy_only=False)[1 : n + 1]
    qs = np.where(prismatic, cm, deg).astype(float)
    return signature_chain(T[: n + 1], joints_to_internal(qs, prismatic), prismatic, T[n + 1])


STAGE = Stage(
    "frames",
    # 4: frames brought to q̄^s with each sweep's recorded readings;
    # 5: imports' sweep points join the tool; 6: the tool sweep's plan.tool_target rows
    # (plan.tool_targets: several targets on the last link, issue 29); 7: a pose set's
    # design start registered by a numpy SVD (Kabsch), not scipy's align_vectors: the
    # same rotation to its last bits (issue 45)
    7,
    ("features", "joints", "positions", "session"),
    NoParams(),
    compute,
    "S-Model frames S̄_0..S̄_n and the tool",
)
