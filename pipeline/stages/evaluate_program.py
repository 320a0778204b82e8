"""Stage ``evaluate_program``: each controller's joint program for every taught task.

Per controller (design, signature, compensated; :mod:`pipeline.evaluation.controllers`):
teach the workspace frame from the recorded readings with the controller's own
forward kinematics (Section 6.5), put the task's points in it with the
constant tool orientation, and solve for the joints on the planned Puma branch
(arms with fewer than six joints: for their task axes about the taught frame's axes).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.evaluation.controllers import (
    CompensatedModel,
    DesignModel,
    SignatureModel,
    flange_angle,
    task_branches,
)
from pipeline.evaluation.geometry import workspace_from_points
from pipeline.evaluation.tasks import tasks_for
from pipeline.kinematics.chain import SerialChain
from pipeline.kinematics.transforms import trans
from pipeline.stages.base import NoParams, Stage
from pipeline.stages.evaluate_teach import joint_columns, joints_from_columns
from pipeline.stages.frames import readings_at, tool_point_rows
from pipeline.stages.positions import positions, sweep_rows, sweep_targets
from pipeline.stages.session import session_plan, session_robot
from pipeline.units import joints_to_boundary, joints_to_internal


def nominal_tool(session: pa.Table) -> np.ndarray:
    """Nominal probe on the last link (4, 4), from the recorded measurement plan."""
    return trans(*session_plan(session)["tool_local_cm"])


def compute(inputs: Mapping[str, Any], params: NoParams) -> pa.Table:
    robot = session_robot(inputs["session"])
    pris = robot.prismatic
    tool = nominal_tool(inputs["session"])
    sig = inputs["signature"]
    design = DesignModel(robot, tool)
    signature = SignatureModel(sig, flange_angle(sig.chain, *_last_link_points(inputs, sig.chain)))
    models = (design, signature, CompensatedModel(design, signature))
    teach = inputs["evaluate_teach"]
    names = teach.column("task").to_pylist()
    points = teach.column("point").to_pylist()
    q_all = joints_to_internal(joints_from_columns(teach), pris)
    cols: dict[str, list[Any]] = {
        k: [] for k in ("task", "controller", "point", "x_cm", "y_cm", "z_cm", "q", "ok")
    }
    for task in tasks_for(robot, tool):
        # Teach points 1, 2, 3 in that order (by their key, not as recorded).
        rows = sorted((k for k, n in enumerate(names) if n == task.name), key=points.__getitem__)
        if len(rows) != 3:
            continue  # not taught: the rig could not reach it (reported by evaluate)
        q_teach = q_all[rows]
        _, branches = task_branches(robot, tool, task)
        for model in models:
            P = model.fk(q_teach)[:, :3, 3]
            W = workspace_from_points(P[0], P[1], P[2])  # Section 6.5
            q, ok = model.solve(W @ task.targets(), branches, q_teach[0], W)
            m = len(q)
            cols["task"] += [task.name] * m
            cols["controller"] += [model.name] * m
            cols["point"] += list(range(1, m + 1))
            for k, c in enumerate(("x_cm", "y_cm", "z_cm")):
                cols[c] += task.points_cm[:, k].tolist()
            cols["q"] += list(joints_to_boundary(q, pris))
            cols["ok"] += ok.tolist()
    q = np.array(cols.pop("q"), float).reshape(-1, robot.n_joints)
    return pa.table(
        {
            "task": cols["task"],
            "controller": cols["controller"],
            "point": np.array(cols["point"], np.int32),
            "x_cm": np.array(cols["x_cm"], float),
            "y_cm": np.array(cols["y_cm"], float),
            "z_cm": np.array(cols["z_cm"], float),
            **joint_columns(q, [j.unit for j in robot.joints]),
            "ok": np.array(cols["ok"], bool),
        }
    )


STAGE = Stage(
    "evaluate_program",
    2,  # 2: the compensated controller (issue 30)
    ("evaluate_teach", "signature", "session", "joints", "positions"),
    NoParams(),
    compute,
    "joint programs of the design, signature and compensated controllers",
)


def _last_link_points(
    inputs: Mapping[str, Any], chain: SerialChain
) -> tuple[np.ndarray, np.ndarray]:
    """Joint values (m, n) deg / cm and positions (m, 3) cm of a target on the last link,
    for :func:`~pipeline.evaluation.controllers.flange_angle`: the last sweep's first
    target (paired by ``(sweep, step)``), or, in a session without it (a pose set), every
    measurement of the tool point (:func:`~pipeline.stages.frames.tool_point_rows`)."""
    n = chain.n_joints
    joints, pos = inputs["joints"], inputs["positions"]
    targets = sweep_targets(pos, n)
    if not targets:
        return tool_point_rows(inputs, n, chain.prismatic)
    rows = sweep_rows(pos, n, targets[0])
    steps = rows.column("step").to_numpy().astype(np.int64)
    return readings_at(joints, n, steps, n, chain.prismatic), positions(rows)
