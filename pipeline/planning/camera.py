"""``pipeline plan --sensor camera``: which poses calibrate an arm best with a camera (issue 39).

The tracker's planner (:mod:`pipeline.planning`) with the camera's measurement:

- **candidates**: random configurations within the joint limits whose target a detector
  would keep, drawn and checked as ``pipeline simulate --sensor camera`` draws them
  (:func:`pipeline.rig.camera.draw_images` at the simulated rig's placement,
  :func:`pipeline.rig.camera.placement`, of the design chain; the lens as stated, with
  the given distortion);
- **information**: the camera fit's whitened pixel Jacobian of every candidate image
  (:class:`~pipeline.refine.camera_block.CameraBlock` of the design's exact pixels, the
  model :func:`~pipeline.refine.camera_fit.camera_model` builds: the chain in the fixed
  body's frame, both hand-eye transforms and the nine intrinsics, fitted), its rows
  weighed with the encoders' rounding that all of them share (a generalised least
  squares' information: one reading error moves the whole image). An image's pixels
  depend on the parameters only through the tool body's pose (6) and the lens (9), so its
  information has rank :data:`IMAGE_RANK` and is kept as that many rows before the
  greedy's Woodbury step (:func:`pipeline.refine.plan.greedy_plan`);
- **criterion**: the predicted RMS tool error over the workspace, the tracker planner's,
  but raw (no alignment): a camera's frames are physical, nothing re-aligns its
  signature, and the camera audit compares the tool point raw
  (:mod:`pipeline.stages.camera_uncertainty`, :mod:`pipeline.rig.camera_audit`); the
  lens is marginalised (its rows of ``M`` zero);
- **prediction**: of the chosen images and of the first as many candidates (random
  visible poses), the fit's covariance at the design: the pixels' and the encoders'
  rounding shared by each image's points (:mod:`pipeline.refine.camera_readings`, as
  ``camera_fit`` states it: the fit weighs the pixels alone, and its covariance adds the
  readings' share as a sandwich).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, positive_in_range
from pipeline.planning import WORKSPACE, Plan, prediction
from pipeline.robots.description import RobotDescription
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.target import Target

#: The rank of one image's pixel Jacobian: the tool body's pose (6) and the lens (9).
IMAGE_RANK = 15
#: Candidate images linearised at once: ~70 rows each, so ~30 MB of Jacobian per batch.
BATCH = 500
#: Candidates by default: fewer than the tracker's 10,000 (each image is 15 rows, not 3),
#: and at most: the greedy holds ~4 arrays of (K, 15, P) and (K, 15, 15), ~0.4 GB at 20,000.
CANDIDATES = 3000
MAX_CANDIDATES = 20_000


@dataclass(frozen=True)
class CameraRig:
    """The camera as the plan sees it: the set-up, the target, the lens (nominal focal
    length, centred, the given distortion) and σ of the pixels (px per coordinate)."""

    setup: str
    target: Target
    lens: Intrinsics
    sigma_px: float


@dataclass(frozen=True)
class _Design:
    """The design rig: the fixed body in the design's base and the body on the flange
    (4, 4 each, cm), and ``q̄ˢ`` (n, internal units)."""

    fixed: np.ndarray
    on_flange: np.ndarray
    q_signature: np.ndarray


def camera_rig(
    setup: str, target: Target, resolution_px: tuple[int, int], focal_px: float,
    distortion: tuple[float, ...], pixel_noise_px: float,
) -> CameraRig:  # fmt: skip
    """The :class:`CameraRig` of ``simulate --sensor camera``'s options: the rig's
    nominal lens with the given distortion, σ the stated one when the noise is 0."""
    from pipeline.rig import camera

    nominal = camera.nominal_intrinsics(*resolution_px, focal_px)
    lens = Intrinsics(nominal.width_px, nominal.height_px, nominal.fx, nominal.fy,
                      nominal.cx, nominal.cy, *distortion)  # fmt: skip
    return CameraRig(setup, target, lens, float(pixel_noise_px or camera.STATED_SIGMA_PX))


def plan_camera_poses(
    robot: RobotDescription,
    rig: CameraRig,
    n_poses: int,
    target_rms_cm: float | None = None,
    candidates: int = CANDIDATES,
    seed: int = 0,
) -> Plan:
    """The plan (module docstring)."""
    from pipeline.rig import camera
    from pipeline.rig.true_robot import ErrorSigmas, draw_true_robot

    positive_in_range("plan: target_rms_cm", target_rms_cm, unit="cm")
    if not (1 <= n_poses <= candidates <= MAX_CANDIDATES):
        raise ArmsigError(
            "plan sizes out of range",
            expected=f"1 <= poses <= candidates <= {MAX_CANDIDATES:,} (camera)",
            got=f"poses {n_poses}, candidates {candidates}",
            fix=f"--poses 40 --candidates {CANDIDATES}",
        )
    # the simulated rig's robot without errors: its base frame is the simulator's (the
    # Puma's is the thesis's, 58.5 cm above the design's), which places the camera; its
    # flange is the design's at every reading
    nominal = draw_true_robot(robot, np.random.default_rng(0), ErrorSigmas(0.0, 0.0, 0.0)).chain
    rng = np.random.default_rng(seed)
    fixed, on_flange = camera.placement(rig.setup, nominal, robot.limits, rig.target, rng)
    q_sig = np.clip(0.0, robot.limits[:, 0], robot.limits[:, 1])  # the simulator's q̄ˢ
    d = _Design(fixed, on_flange, _internal(robot, q_sig))
    q, _ = camera.draw_images(candidates, rig.setup, nominal, robot.limits, rig.target,
                              fixed, on_flange, rig.lens, rng)  # fmt: skip
    chosen, fields = _choose(robot, d.q_signature, len(q), n_poses, target_rms_cm,
                             lambda k: _design_problem(robot, rig, d, q[k]))  # fmt: skip
    return Plan(q=q[chosen], **fields)


def _choose(
    robot: RobotDescription, q_signature: np.ndarray, K: int, n_poses: int,
    target_rms_cm: float | None, problem_of: Callable[[np.ndarray], tuple[Any, np.ndarray]],
) -> tuple[np.ndarray, dict[str, Any]]:  # fmt: skip
    """The images chosen among ``K`` candidates (indices, in the order chosen) and the
    :class:`~pipeline.planning.Plan` fields of their prediction and of the first as many
    candidates'; ``problem_of(indices)``: the camera fit's problem of those candidates
    and its ``x`` (module docstring)."""
    from pipeline.refine.camera_readings import encoder_sigma
    from pipeline.refine.plan import greedy_plan

    problem, x = problem_of(np.arange(min(K, BATCH)))
    names = (*problem.model.param_names, *problem.block.param_names)
    units = (*problem.model.param_units, *problem.block.param_units)
    A, M = _workspace(robot, problem, x, q_signature)
    sigma_q = encoder_sigma(robot.encoder_resolution, robot.prismatic)
    Jc = np.concatenate([_image_rows(*problem_of(np.arange(k, min(k + BATCH, K))), sigma_q)
                         for k in range(0, K, BATCH)])  # fmt: skip
    greedy = greedy_plan(Jc, M, WORKSPACE, units, n_poses, target_rms_cm)
    chosen = greedy.chosen
    pred = _prediction(*problem_of(chosen), names, units, A, M, sigma_q)
    random = _prediction(*problem_of(np.arange(len(chosen))), names, units, A, M, sigma_q)
    return chosen, {**pred, "rms_by_size_cm": greedy.rms_cm, "random_rms_cm": random["rms_cm"]}


def _internal(robot: RobotDescription, q: np.ndarray) -> np.ndarray:
    from pipeline.units import joints_to_internal

    return np.asarray(joints_to_internal(q, robot.prismatic), float)


def _design_problem(
    robot: RobotDescription, rig: CameraRig, d: _Design, q: np.ndarray
) -> tuple[Any, np.ndarray]:
    """The camera fit's problem (its model and pixel block) of images at joint values
    ``q`` (K, n, boundary units) of the design rig, seen exactly: each image's points the
    detector finds (:func:`pipeline.rig.camera.detect`), their pixels the design's, and
    its ``x`` (the residuals zero)."""
    from pipeline.kinematics.chain import link_frames
    from pipeline.refine.camera_fit import Detections, camera_block, camera_model
    from pipeline.refine.camera_start import CameraStart
    from pipeline.refine.solve import Problem
    from pipeline.rig import camera
    from pipeline.sensor.camera import project

    design = robot.design_chain()
    qi = _internal(robot, q)
    flange = link_frames(design, qi)[:, robot.n_joints]
    T = camera.camera_from_target(rig.setup, d.fixed, d.on_flange, flange)
    _, local = rig.target.points()
    _, found, _ = camera.detect(rig.target, T, rig.lens, local)
    uv = project(camera.camera_points(T, local), rig.lens.vector())
    image, point = np.nonzero(found)
    det = Detections(image.astype(np.int64), local[point], uv[image, point],
                     np.full(len(image), rig.sigma_px), qi, d.q_signature)  # fmt: skip
    k = rig.lens.vector()
    start = CameraStart(k, T, d.fixed, d.on_flange)
    model, x_kin = camera_model(det, design, start, rig.setup)
    block = camera_block(det, rig.setup, k, rig.lens, "fitted", None)
    return Problem(model, block, "linear"), np.concatenate([x_kin, k])


def _image_rows(problem: Any, x: np.ndarray, sigma_q: np.ndarray) -> np.ndarray:
    """Every image's information compressed to :data:`IMAGE_RANK` rows (K, r, P), ``Jcᵀ
    Jc = Jᵀ (I + G Σ_q Gᵀ)⁻¹ J``: its whitened pixel rows ``J`` weighed with the error its
    readings share (``G = ∂r/∂q``, :func:`pipeline.refine.camera_readings.reading_jacobian`;
    ``Σ_q = diag(sigma_q²)``), by the Woodbury identity ``JᵀJ − JᵀGs (I + Gsᵀ Gs)⁻¹ GsᵀJ``,
    ``Gs = G diag(sigma_q)``; ``Jc = Λ^½ Vᵀ`` of its largest eigenvalues."""
    from pipeline.refine.camera_readings import reading_jacobian
    from pipeline.refine.solve import residuals_and_jacobian

    J = residuals_and_jacobian(problem, x)[1]
    Gs = reading_jacobian(problem.block, problem.model, x) * sigma_q
    image = np.repeat(problem.block.image, 2)
    K, P, n = len(problem.model.theta), J.shape[1], Gs.shape[1]
    count = np.bincount(image, minlength=K)
    rank_in_image = np.arange(len(image)) - np.repeat(np.cumsum(count) - count, count)
    rows, G = np.zeros((K, int(count.max()), P)), np.zeros((K, int(count.max()), n))
    rows[image, rank_in_image], G[image, rank_in_image] = J, Gs
    JtG = np.swapaxes(rows, 1, 2) @ G  # (K, P, n)
    C = np.eye(n) + np.swapaxes(G, 1, 2) @ G
    info = np.swapaxes(rows, 1, 2) @ rows - JtG @ np.linalg.solve(C, np.swapaxes(JtG, 1, 2))
    lam, V = np.linalg.eigh(0.5 * (info + np.swapaxes(info, 1, 2)))  # ascending
    r = min(IMAGE_RANK, P)
    return np.asarray(np.sqrt(np.clip(lam[:, -r:], 0.0, None))[:, :, None]
                      * np.swapaxes(V[:, :, -r:], 1, 2))  # fmt: skip


def _workspace(
    robot: RobotDescription, problem: Any, x: np.ndarray, q_signature: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The raw error maps ``A`` (m, 6, n_kin) of the tool point at the workspace's
    configurations (the uncertainty stage's) and their information ``M`` (P, P), the
    lens's rows zero (module docstring)."""
    from pipeline.refine.camera_fit import observing
    from pipeline.refine.plan import workspace_information
    from pipeline.refine.uncertainty import model_error_maps

    model = problem.model
    at = observing(model, robot.random_configurations(WORKSPACE, 0), q_signature)
    A, _ = model_error_maps(at, x[: model.n_params])
    M = np.zeros((len(x), len(x)))
    M[: model.n_params, : model.n_params] = workspace_information(A)
    return A, M


def _prediction(
    problem: Any, x: np.ndarray, names: tuple[str, ...], units: tuple[str, ...],
    A: np.ndarray, M: np.ndarray, sigma_q: np.ndarray,
) -> dict[str, Any]:  # fmt: skip
    """:func:`pipeline.planning.prediction` of the images of ``problem`` at ``x``: the
    fit's covariance, the pixels' (with the planner's weak prior) and the encoders'
    rounding (σ ``sigma_q``) shared by each image's points, as ``camera_fit`` states it
    (module docstring)."""
    from pipeline.refine.camera_readings import reading_covariance
    from pipeline.refine.plan import design_covariance
    from pipeline.refine.solve import residuals_and_jacobian

    J = residuals_and_jacobian(problem, x)[1]
    unscaled = design_covariance(J[None], units)
    cov = unscaled + reading_covariance(problem.block, problem.model, x, J, unscaled, sigma_q)
    return prediction(J[None], names, units, A, A, M, cov, len(problem.block.image))


def plan_from_camera_session(
    session_dir: str | Path, n_poses: int, target_rms_cm: float | None = None
) -> tuple[RobotDescription, Plan]:
    """The ``n_poses`` most informative images of an identified camera session (``plan
    --from``), for a re-calibration with fewer: the candidates are the session's images,
    each with the points it detected, seen through its fitted chain and lens, chosen as
    :func:`plan_camera_poses` chooses; the comparison is its first ``n_poses`` images."""
    from pipeline.refine.camera_fit import Detections, camera_block, observing
    from pipeline.refine.solve import Problem
    from pipeline.stages.camera_fit import detections_for_fit, fit_pixels, fitted_model
    from pipeline.stages.runner import stage_path
    from pipeline.stages.session import session_robot
    from pipeline.stages.tables import read_table
    from pipeline.units import joints_to_boundary

    sdir = Path(session_dir)
    names = ("session", "joints", "detections", "camera_fit")
    if not all(stage_path(sdir, n).is_file() for n in names):
        raise ArmsigError(f"{sdir}: not an identified camera session with joint readings",
                          fix=f"run `pipeline identify {sdir}` first")  # fmt: skip
    tables = {n: read_table(stage_path(sdir, n)) for n in names}
    robot = session_robot(tables["session"])
    det, _, lens, setup = detections_for_fit(tables)
    model, x_kin, k, q_sig = fitted_model(tables["camera_fit"], robot)
    if not 1 <= n_poses <= det.n_images:
        raise ArmsigError("plan --from: more images asked than the session holds",
                          expected=f"1 to {det.n_images} images", got=str(n_poses),
                          fix=f"--poses {min(det.n_images, 20)}")  # fmt: skip

    def problem_of(idx: np.ndarray) -> tuple[Any, np.ndarray]:
        place = np.full(det.n_images, -1)
        place[idx] = np.arange(len(idx))  # each image's place among the candidates idx
        use = np.flatnonzero(place[det.image] >= 0)
        use = use[np.argsort(place[det.image[use]], kind="stable")]  # sorted by image
        sub = Detections(place[det.image[use]].astype(np.int64), det.local[use], det.uv[use],
                         det.sigma_px[use], det.q[idx], q_sig)  # fmt: skip
        block = camera_block(sub, setup, k, lens, "fitted", None)
        return Problem(observing(model, det.q[idx], q_sig), block, "linear"), np.r_[x_kin, k]

    chosen, fields = _choose(robot, q_sig, det.n_images, n_poses, target_rms_cm, problem_of)
    q = joints_to_boundary(det.q[chosen], robot.prismatic)
    rig = json.loads(tables["session"].column("rig_json")[0].as_py())
    steps = fit_pixels(rig, tables["detections"])[0][chosen]  # the images' recorded steps
    return robot, Plan(q=q, **fields, source_steps=tuple(int(v) for v in steps))
