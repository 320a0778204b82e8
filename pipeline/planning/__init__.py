"""``pipeline plan``: how many poses, and which, for a wanted accuracy (issue 28).

Before anyone books a tracker: candidates are drawn inside the joint limits with the tool
in front of the tracker (the simulated rig's placement and visibility, as ``pipeline
simulate --poses`` draws them), the design model predicts each candidate's information
(:mod:`pipeline.refine.plan`: position noise of the tracker's law, or ``sigma_cm``, plus
the encoders' rounding), and the poses that minimise the predicted RMS tool error over
the workspace are chosen greedily, up to ``n_poses`` or until ``target_rms_cm`` is met
with 95 % probability (:data:`pipeline.refine.plan.TARGET_QUANTILE`).
The plan is a CSV of joint readings (:mod:`pipeline.rig.pose_file`); ``pipeline simulate
--plan`` records exactly it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, positive_in_range
from pipeline.refine.held_joints import whitening
from pipeline.refine.identifiability import analyse
from pipeline.refine.kinematics import ChainModel, chain_model
from pipeline.refine.plan import (
    greedy_plan,
    predicted_rms_cm,
    rms_quantile_cm,
    workspace_information,
)
from pipeline.refine.points import PointBlock
from pipeline.refine.uncertainty import model_error_maps, predict, tool_model
from pipeline.robots.description import RobotDescription
from pipeline.stages.recording_points import MAX_SIGMA_CM, MIN_SIGMA_CM
from pipeline.sweeps import POSES_SWEEP, TOOL_SWEEP, WHOLE_ARM_SWEEPS
from pipeline.units import joints_to_internal

#: Candidates drawn by default: 10,000 random poses cover a 6-axis workspace densely
#: enough that a plan of 30-100 rarely needs a pose it does not hold.
CANDIDATES = 10_000
#: Workspace configurations the predicted error is averaged over: the audit's 1,000.
WORKSPACE = 1000


@dataclass(frozen=True)
class Plan:
    """A chosen pose set (joint values, boundary units), its predicted RMS and 95 % tool
    errors (cm) over the workspace, the RMS the audit stays under with 95 % probability,
    the predicted RMS of every shorter prefix, the same number of uniformly random
    candidates for comparison, and the parameters it cannot identify."""

    q: np.ndarray
    rms_cm: float
    p95_cm: float
    rms_q95_cm: float
    rms_by_size_cm: np.ndarray
    random_rms_cm: float
    unidentified: tuple[str, ...] = field(default=())
    source_steps: tuple[int, ...] = field(default=())  # plan --from: the session's poses

    def to_dict(self) -> dict[str, Any]:
        return {
            "poses": len(self.q),
            **({"session_steps": list(self.source_steps)} if self.source_steps else {}),
            "predicted_rms_cm": self.rms_cm,
            "predicted_p95_cm": self.p95_cm,
            "predicted_rms_q95_cm": self.rms_q95_cm,
            "random_predicted_rms_cm": self.random_rms_cm,
            "rms_by_size_cm": self.rms_by_size_cm.tolist(),
            "unidentified": list(self.unidentified),
        }


def design_model(
    robot: RobotDescription,
    sensor_from_base: np.ndarray,
    sweep: np.ndarray,
    local: dict[int, np.ndarray],
    q: np.ndarray,
) -> tuple[ChainModel, np.ndarray]:
    """The design model observing, at joint values ``q`` (K, n, boundary), the point of
    each observation's ``sweep`` (K,): joint sweep ``j``'s target at ``local[j]`` (3,) in
    the frame moving with joint ``j``, the tool point at ``local[TOOL_SWEEP]`` (the last
    link's frame) for the tool sweep and a pose set; its frames taken at zero readings (a
    gauge: any q̄ˢ predicts alike), and its ``x``."""
    from pipeline.kinematics.chain import link_frames
    from pipeline.rig.plan import target_positions, tool_positions

    n, pris = robot.n_joints, robot.prismatic
    chain, zero = robot.design_chain(), np.zeros(n)
    F = sensor_from_base @ link_frames(chain, zero)
    model = chain_model(sweep, ["T1"] * len(q), joints_to_internal(q, pris), F[:n], pris)
    seen = [int(sweep[np.argmax(model.point == j)]) for j in range(model.n_points)]
    p0 = [
        tool_positions(chain, sensor_from_base, zero, local[TOOL_SWEEP])
        if s in WHOLE_ARM_SWEEPS
        else target_positions(chain, sensor_from_base, zero, s, local[s])
        for s in seen
    ]
    x = np.concatenate([np.zeros(model.n_axis_params), *p0])
    return model, x


def whitened(
    model: ChainModel, x: np.ndarray, robot: RobotDescription, cov_cm2: np.ndarray
) -> np.ndarray:
    """Whitened Jacobians (K, 3, P): :func:`whitening` times the position Jacobians."""
    return np.asarray(whitening(model, x, robot, cov_cm2) @ model.position_jacobian(x))


def plan_poses(
    robot: RobotDescription,
    n_poses: int,
    target_rms_cm: float | None = None,
    sigma_cm: float | None = None,
    candidates: int = CANDIDATES,
    seed: int = 0,
) -> Plan:
    """The plan (module docstring): ``sigma_cm`` None takes the simulated tracker's law."""
    positive_in_range("plan: sigma_cm", sigma_cm, MIN_SIGMA_CM, MAX_SIGMA_CM, unit="cm")
    positive_in_range("plan: target_rms_cm", target_rms_cm, unit="cm")
    if not (1 <= n_poses <= candidates and 1 <= candidates <= 1_000_000):
        raise ArmsigError(
            "plan sizes out of range",
            expected="1 <= poses <= candidates <= 1,000,000",
            got=f"poses {n_poses}, candidates {candidates}",
            fix="--poses 50 --candidates 10000",
        )
    q, model, x, J = _candidates(robot, sigma_cm, candidates, seed)
    theta = robot.random_configurations(WORKSPACE, 0)  # the audit's; q̄ˢ = 0 (the gauge)
    chosen, fields = _choose(J, model, x, theta, n_poses, target_rms_cm)
    return Plan(q=q[chosen], **fields)


def _candidates(
    robot: RobotDescription, sigma_cm: float | None, candidates: int, seed: int
) -> tuple[np.ndarray, ChainModel, np.ndarray, np.ndarray]:
    """Random visible candidates (K, n, boundary units), their design model, its ``x``
    and their whitened Jacobians (K, 3, P) (module docstring)."""
    from pipeline.rig import tracker
    from pipeline.rig.plan import PROBE_LENGTH_CM, default_sensor_from_base
    from pipeline.sensor.geometry import default_geometry

    placement = default_sensor_from_base(robot)
    tool = tracker.pose_tool_local((0.0, 0.0, PROBE_LENGTH_CM))
    rng = np.random.default_rng(seed)
    q = tracker.check_configurations(
        candidates, robot.limits, robot.design_chain(), placement, tool, default_geometry(), rng
    )
    model, x = design_model(robot, placement, np.full(len(q), POSES_SWEEP), {TOOL_SWEEP: tool}, q)
    p = model.positions(x)
    sig = tracker.sigma_cm(p) if sigma_cm is None else np.full(len(p), float(sigma_cm))
    return q, model, x, whitened(model, x, robot, sig[:, None, None] ** 2 * np.eye(3))


def design_bounds(
    robot: RobotDescription, n_poses: int, candidates: int = CANDIDATES, draws: int = 20
) -> dict[str, float]:
    """How much a plan of ``n_poses`` can gain over as many random poses, from the
    information matrices alone (issue 28): the predicted RMS (cm) of the greedy plan, the
    median over ``draws`` seeded random sets of the candidates, and the least any
    ``n_poses`` of them can predict (:func:`pipeline.refine.plan.continuous_design`)."""
    from pipeline.refine.plan import continuous_design

    q, model, x, J = _candidates(robot, None, candidates, 0)
    A, B = model_error_maps(tool_model(model, robot.random_configurations(WORKSPACE, 0)), x)
    M = workspace_information(B)
    units = model.param_units
    rng = np.random.default_rng(1)
    rand = [
        predicted_rms_cm(J[rng.choice(len(J), n_poses, replace=False)], M, WORKSPACE, units)
        for _ in range(draws)
    ]
    design = continuous_design(J, M, units)
    return {
        "greedy_cm": float(greedy_plan(J, M, WORKSPACE, units, n_poses).rms_cm[-1]),
        "random_median_cm": float(np.median(rand)),
        "continuous_cm": float(np.sqrt(design.criterion / n_poses / WORKSPACE)),
        "bound_cm": float(np.sqrt(design.bound / n_poses / WORKSPACE)),
    }


def _choose(
    J: np.ndarray,
    model: ChainModel,
    x: np.ndarray,
    theta: np.ndarray,
    n_poses: int,
    target_rms_cm: float | None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """The candidates chosen (indices into the whitened Jacobians ``J`` (K, 3, P) of
    ``model`` at ``x``, in the order chosen) and the :class:`Plan` fields of their
    prediction over the workspace configurations ``theta`` (m, n, from q̄ˢ); the random
    comparison is the first as many candidates."""
    A, B = model_error_maps(tool_model(model, theta), x)
    M = workspace_information(B)
    units = model.param_units
    plan = greedy_plan(J, M, WORKSPACE, units, n_poses, target_rms_cm)
    chosen = plan.chosen
    fields = {
        **prediction(J[chosen], model.param_names, model.param_units, A, B, M, plan.covariance),
        "rms_cm": float(plan.rms_cm[-1]),  # the greedy's own (the same, to rounding)
        "rms_q95_cm": plan.rms_quantile_cm,
        "rms_by_size_cm": plan.rms_cm,
        "random_rms_cm": predicted_rms_cm(J[: len(chosen)], M, WORKSPACE, units),
    }
    return chosen, fields


def prediction(
    J: np.ndarray,
    names: tuple[str, ...],
    units: tuple[str, ...],
    A: np.ndarray,
    B: np.ndarray,
    M: np.ndarray,
    cov: np.ndarray,
    n_points: int | None = None,
) -> dict[str, Any]:
    """The predicted RMS, its 95 % quantile over robots, the 95 % over the workspace (cm)
    and the parameters not identifiable, of a measurement whose whitened Jacobians are
    ``J`` (K, r, P) and covariance ``cov`` (P, P) of the parameters ``names`` (their
    internal ``units``), with the workspace's error maps ``A``, ``B`` (m, 6, n_kin: the
    first n_kin parameters, the chain's) and their information ``M``
    (:func:`pipeline.refine.plan.workspace_information`, zero beyond the chain);
    ``n_points``: points measured (default K)."""
    ident = analyse(J.reshape(-1, J.shape[-1]), units, True, n_points or len(J))
    n_kin = A.shape[-1]
    pred = predict(A, B, cov[:n_kin, :n_kin])
    return {
        "rms_cm": float(np.sqrt(max(np.trace(M @ cov), 0.0) / WORKSPACE)),
        "p95_cm": float(np.percentile(pred.position_aligned_cm, 95)),
        "rms_q95_cm": rms_quantile_cm(cov, M, WORKSPACE),
        "unidentified": tuple(names[k] for k in np.flatnonzero(ident.held)),
    }


def write_plan(
    path: str | Path,
    robot: RobotDescription,
    plan: Plan,
    force: bool = False,
    inputs: Sequence[str | Path] = (),
    sensor: str = "",
) -> Path:
    """Write ``plan`` as a pose plan file (:mod:`pipeline.rig.pose_file`); an existing file
    is refused unless ``force``, and never one of the command's ``inputs``
    (:func:`pipeline.atomic.check_new_file`); ``sensor``: what it plans for, when not a
    tracker (``camera eye-to-hand``), in its first line."""
    from pipeline.atomic import check_new_file
    from pipeline.rig.pose_file import write_pose_plan

    out = Path(path)
    check_new_file(out, "pose plan", force, inputs)
    comment = (
        f"armsig pose plan: {robot.name}{', ' + sensor if sensor else ''}, {len(plan.q)} "
        "poses; predicted RMS "
        f"{plan.rms_cm:.3g} cm (under {plan.rms_q95_cm:.3g} cm with 95 % probability), "
        f"95 % {plan.p95_cm:.3g} cm over the workspace "
        f"(as many random poses: {plan.random_rms_cm:.3g} cm)"
    )
    return write_pose_plan(out, robot, plan.q, comment)


def plan_from_session(
    session_dir: str | Path, n_poses: int, target_rms_cm: float | None = None
) -> tuple[RobotDescription, Plan]:
    """The ``n_poses`` most informative poses of an identified session's pose set (issue
    28, ``pipeline plan --from``), for a re-calibration with fewer poses: the candidates
    are the session's poses of its tool target, each with its own recorded noise (the
    refinement's whitening) and the Jacobian of the session's signature (its refined
    chain and non-geometric terms), chosen as :func:`plan_poses` chooses. The random
    comparison is the session's first ``n_poses`` poses in step order."""
    from pipeline.signature.file import FILE_NAME
    from pipeline.signature.session import load_session_document
    from pipeline.stages.frames import chain_from_frames, pose_tool_target, readings_at
    from pipeline.stages.refine import problem_params, refine_summary, refined_x
    from pipeline.stages.refine_problem import session_problem
    from pipeline.stages.runner import stage_path
    from pipeline.stages.session import session_plan, session_robot
    from pipeline.stages.tables import read_table

    sdir = Path(session_dir)
    if stage_path(sdir, "camera_fit").is_file():  # issue 39: a camera's images are not planned
        raise ArmsigError(
            f"{sdir}: plan --from chooses among a tracker's poses, not a camera's images",
            expected="a tracker or digitizer session with a pose set",
            fix="choose among a camera session's images with `pipeline plan OUT --from "
            "SESSION` (pipeline.planning.camera.plan_from_camera_session)",
        )
    names = ("session", "joints", "positions", "frames", "refine")
    if not all(stage_path(sdir, n).is_file() for n in names):
        raise ArmsigError(f"{sdir}: not identified", fix=f"run `pipeline identify {sdir}` first")
    load_session_document(sdir / FILE_NAME)  # refused when stale, as `export` refuses it
    tables = {n: read_table(stage_path(sdir, n)) for n in names}
    summary = refine_summary(tables["refine"])
    plan = session_plan(tables["session"])
    if "poses" not in plan or not summary.get("enabled", False):
        raise ArmsigError(
            f"{sdir}: no refined pose set to choose from",
            expected="a session with a pose set (sweep poses), identified with the refinement",
            fix="plan new poses with `pipeline plan OUT --robot ROBOT --poses N`",
        )
    robot = session_robot(tables["session"])
    sp = session_problem(tables, **problem_params(summary))
    model = sp.problem.model
    x = refined_x(tables["refine"])
    keys = sp.problem.block.keys
    sweep, step = keys.column("sweep").to_numpy(), keys.column("step").to_numpy()
    tool = pose_tool_target(plan, tables["positions"])
    sel = np.flatnonzero(
        (sweep == POSES_SWEEP) & (np.array(keys.column("target").to_pylist()) == tool)
    )
    if not 1 <= n_poses <= len(sel):
        raise ArmsigError(
            "plan --from: more poses asked than the session holds",
            expected=f"1 to {len(sel)} poses",
            got=str(n_poses),
            fix=f"--poses {min(len(sel), 60)}",
        )
    n_kin = model.n_params
    J = model.position_jacobian(x[:n_kin])  # (K, 3, P)
    block = sp.problem.block
    assert isinstance(block, PointBlock)  # a pose set is a point sensor's
    Jw = (block.whiten @ J)[sel]  # each position's own noise (its whitening)
    q_sig = chain_from_frames(tables["frames"], robot.prismatic).joint_offsets
    theta = robot.random_configurations(WORKSPACE, 0) - q_sig  # the uncertainty stage's
    chosen, prediction = _choose(Jw, model, x[:n_kin], theta, n_poses, target_rms_cm)
    steps = step[sel][chosen]
    q = readings_at(tables["joints"], POSES_SWEEP, np.sort(steps), robot.n_joints, robot.prismatic)
    q = q[np.argsort(np.argsort(steps))]  # in the order chosen
    return robot, Plan(q=q, **prediction, source_steps=tuple(int(v) for v in steps))
