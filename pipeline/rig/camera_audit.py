"""Audit a camera fit against the simulated rig's truth (only the audits and the tests
read ``rig-truth.json``).

Three comparisons, none of which the fit can pass by convention:

- **tool pose**: the pose of the body on the flange (the target for eye-to-hand, the
  camera for eye-in-hand) in the frame of the fixed one, predicted by the fitted chain
  at random configurations within the limits against the truth's (cm, deg). Both frames
  are physical, so no alignment is fitted: this is the tracker audit's tool point, and
  the camera-from-target transform of every configuration;
- **hand-eye**: both transforms in the truth's base (world) and flange (last link)
  frames. A fitted chain has its own base and flange conventions (its base is joint 1's
  axis line, its tool the body itself), so the fitted model is carried into the truth's
  frames by the alignment ``F_true(q) ≈ X · T_fit(q) · Y``
  (:func:`pipeline.kinematics.alignment.fit_alignment`): ``X`` is then the fixed body in
  the base, ``Y⁻¹`` the moving one on the flange;
- **intrinsics**: each against the true lens, relative (to max(|true|, 1): the
  distortion coefficients are near zero).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.alignment import fit_alignment
from pipeline.kinematics.chain import link_frames
from pipeline.kinematics.so3 import vector_from_rotation
from pipeline.kinematics.transforms import invert_transform
from pipeline.refine.camera_fit import CameraFit, tool_poses
from pipeline.rig.audit import true_chain
from pipeline.sensor.camera import Intrinsics
from pipeline.units import joints_to_internal

#: Random configurations of the audit: enough to reach the limits' corners.
CONFIGURATIONS = 1000


@dataclass(frozen=True)
class CameraAudit:
    """Largest errors over the audit's configurations (cm, deg, relative)."""

    tool_position_cm: float
    tool_orientation_deg: float
    fixed_position_cm: float  # camera (eye-to-hand) or target (eye-in-hand) in the base
    fixed_orientation_deg: float
    flange_position_cm: float  # target (eye-to-hand) or camera (eye-in-hand) on the flange
    flange_orientation_deg: float
    intrinsics_relative: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def pose_errors(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (cm) and rotation angle (deg) between poses ``A`` and ``B`` (..., 4, 4)."""
    dR = np.swapaxes(A[..., :3, :3], -1, -2) @ B[..., :3, :3]
    angle = np.linalg.norm(vector_from_rotation(dR), axis=-1)
    return np.linalg.norm(A[..., :3, 3] - B[..., :3, 3], axis=-1), np.degrees(angle)


def true_hand_eye(truth: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """The true (fixed body in the world, moving body on the flange), (4, 4) each."""
    cam = truth["camera"]
    if cam["setup"] == "eye-to-hand":
        return np.array(cam["camera_in_world"]), np.array(cam["target_in_flange"])
    return np.array(cam["target_in_world"]), np.array(cam["camera_in_flange"])


def audit_camera_fit(
    fit: CameraFit, truth: dict[str, Any], robot: Any, q_signature: np.ndarray, seed: int = 0
) -> CameraAudit:
    """The fit against the truth (module docstring); ``robot``: the design description
    (its limits), ``q_signature``: the fit's ``q̄^s`` (rad / cm)."""
    x = fit.solution.x[: fit.model.n_params]
    return _audit(fit.model, x, fit.intrinsics, q_signature, truth, robot, seed)


def audit_camera_session(session_dir: str | Path, seed: int = 0) -> CameraAudit:
    """The ``camera_fit`` stage of a simulated camera session against its truth."""
    from pipeline.rig.audit import read_truth
    from pipeline.stages.camera_fit import fitted_model
    from pipeline.stages.runner import stage_path
    from pipeline.stages.session import session_robot
    from pipeline.stages.tables import read_table

    sdir = Path(session_dir)
    path = stage_path(sdir, "camera_fit")
    if not path.is_file():
        raise ArmsigError(f"{sdir}: no camera fit yet", fix=f"run `pipeline identify {sdir}`")
    robot = session_robot(read_table(stage_path(sdir, "session")))
    model, x, intrinsics, q_sig = fitted_model(read_table(path), robot)
    truth = read_truth(sdir / "rig-truth.json")
    return _audit(model, x, intrinsics, q_sig, truth, robot, seed)


def _audit(
    model: Any, x: np.ndarray, intrinsics: np.ndarray, q_signature: np.ndarray,
    truth: dict[str, Any], robot: Any, seed: int,
) -> CameraAudit:  # fmt: skip
    chain = true_chain(truth)  # in the sensor frame: the fixed body's
    lim = robot.limits
    rng = np.random.default_rng(seed)
    q = joints_to_internal(rng.uniform(lim[:, 0], lim[:, 1], (CONFIGURATIONS, len(lim))),
                           robot.prismatic)  # fmt: skip
    fixed, on_flange = true_hand_eye(truth)
    flange = link_frames(chain, q)[:, robot.n_joints]
    T_fit = tool_poses(model, x, q, q_signature)
    tool_p, tool_a = pose_errors(flange @ on_flange, T_fit)
    world_flange = fixed @ flange  # the sensor frame is the fixed body's
    X, Y = fit_alignment(world_flange, T_fit)
    fix_p, fix_a = pose_errors(X, fixed)
    fl_p, fl_a = pose_errors(invert_transform(Y), on_flange)
    true_k = Intrinsics.from_dict(truth["camera"]["intrinsics_true"]).vector()
    rel = np.abs(intrinsics - true_k) / np.maximum(np.abs(true_k), 1.0)
    return CameraAudit(float(tool_p.max()), float(tool_a.max()), float(fix_p), float(fix_a),
                       float(fl_p), float(fl_a), float(rel.max()))  # fmt: skip
