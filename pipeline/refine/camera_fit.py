"""The camera's whole-chain fit: the arm, both hand-eye transforms and the lens from pixels.

Parameters (Ceres style, each declared once):

- the chain, as for a pose set (:mod:`pipeline.refine.kinematics`: the axis lines of every
  joint, started at the design), in the frame of the part fixed in the cell (the camera
  for eye-to-hand, the target for eye-in-hand: the session's *sensor frame*). Joint 1's
  axis line in that frame is the fixed hand-eye transform (camera in base, or target in
  base) up to the base's gauge (its origin along the axis and turn about it: conventions,
  gauge 2 of the chain model);
- the tool: the body on the flange (the target for eye-to-hand, the camera for
  eye-in-hand) as the tool point (its origin, ``tool.x, y, z``) and the tool's rotation
  (``tool_rot.rx, ry, rz``): the flange hand-eye transform;
- the intrinsics (``camera.fx`` … ``camera.k3``): fitted, held at their start
  (``intrinsics="fixed"``), or fitted with a prior (``prior_sigma``).

Residuals: :class:`~pipeline.refine.camera_block.CameraBlock` (σ in px, the refinement's
robust loss). The start is closed form, as the peers do it (:func:`camera_start`):

1. the lens and every image's target pose: ``cv2.calibrateCamera`` from the nominal lens
   (Zhang's method with the nominal as its guess) when the intrinsics are fitted, else
   ``cv2.solvePnP`` per image with the given lens;
2. both hand-eye transforms: ``cv2.calibrateRobotWorldHandEye`` (Shah's method) from the
   design's flange poses at the readings and the per-image poses;
3. the design chain placed by the fixed hand-eye transform; the tool's point and
   rotation from the per-image poses carried back through it
   (:func:`~pipeline.refine.kinematics.start_points`,
   :func:`~pipeline.refine.orientation.start_rotation`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.kinematics.transforms import invert_transform
from pipeline.optim.block import Array
from pipeline.refine.camera_block import EYE_IN_HAND, EYE_TO_HAND, CameraBlock
from pipeline.refine.kinematics import ChainModel, start_points
from pipeline.refine.orientation import OrientationRows, start_rotation
from pipeline.refine.solve import Problem, Solution, solve
from pipeline.sensor.camera import Intrinsics
from pipeline.sweeps import POSES_SWEEP

#: Fewest detected points per image: a planar PnP needs 4; a few more keep it unique.
MIN_POINTS_PER_IMAGE = 6
#: Fewest images: each adds 6 pose unknowns to the start; the chain of a 6-joint arm has
#: ~30 parameters, the lens 9 (the identifiability of the whole is checked by its rank).
MIN_IMAGES = 10
INTRINSICS = ("fitted", "fixed", "prior")


@dataclass(frozen=True)
class Detections:
    """The detected points of a camera session, one row per point, sorted by image.

    ``image`` (D,) the image (0 … m − 1) of each point, ``local`` (D, 3) cm its target
    coordinates, ``uv`` (D, 2) px its pixel, ``sigma_px`` (D,) its σ; ``q`` (m, n) the
    joint values of each image (rad / cm), ``q_signature`` (n,) ``q̄^s``.
    """

    image: npt.NDArray[np.int64]
    local: Array
    uv: Array
    sigma_px: Array
    q: Array
    q_signature: Array

    @property
    def n_images(self) -> int:
        return len(self.q)


@dataclass(frozen=True)
class CameraStart:
    """The closed-form start: the lens, the target's pose in the camera per image (m, 4, 4),
    OpenCV's hand-eye (``fixed_in_base``: camera or target in the design's base frame,
    ``tool_in_flange``: target or camera in the design's last link frame, 4 × 4, cm)."""

    intrinsics: Array
    camera_from_target: Array
    fixed_in_base: Array
    tool_in_flange: Array


@dataclass(frozen=True)
class CameraFit:
    """The fit: its model and solution, the start, names, and the rms pixel residual."""

    model: ChainModel
    block: CameraBlock
    solution: Solution
    start: CameraStart
    names: tuple[str, ...]
    rms_px: float
    x_start: Array  # the closed-form start of every parameter

    @property
    def intrinsics(self) -> Array:
        return self.solution.x[self.model.n_params :]

    def tool_poses(self, q: Array, q_signature: Array) -> Array:
        """The tool body's pose in the sensor frame (m, 4, 4) at joint values ``q`` (m, n)."""
        m = self.model
        at = ChainModel(m.frames0, m.prismatic, np.full(len(q), m.n_joints), q - q_signature,
                        np.zeros(len(q), np.int64), m.point_names, True)  # fmt: skip
        x = self.solution.x[: m.n_params]
        T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
        T[:, :3, :3], T[:, :3, 3] = at.tool_rotations(x), at.positions(x)
        return T


def _check(det: Detections, setup: str, intrinsics: str) -> None:
    if setup not in (EYE_TO_HAND, EYE_IN_HAND) or intrinsics not in INTRINSICS:
        raise StageError(
            f"camera fit: unknown set-up {setup!r} or intrinsics {intrinsics!r}",
            expected=f"{EYE_TO_HAND} or {EYE_IN_HAND}; intrinsics {', '.join(INTRINSICS)}",
        )
    per_image = np.bincount(det.image, minlength=det.n_images)
    if det.n_images < MIN_IMAGES or per_image.min() < MIN_POINTS_PER_IMAGE:
        raise StageError(
            f"camera fit: {det.n_images} images, the sparsest with {per_image.min()} points",
            expected=f"at least {MIN_IMAGES} images of {MIN_POINTS_PER_IMAGE} points or more",
            fix="record more images of the whole target, at poses spread over the workspace",
        )


def _pose(R: Array, t: Array) -> Array:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, np.ravel(t)
    return T


def camera_start(
    det: Detections, design: SerialChain, lens: Intrinsics, setup: str, fit_lens: bool
) -> CameraStart:
    """The closed-form start (module docstring, steps 1 and 2)."""
    import cv2

    obj = [det.local[det.image == i].astype(np.float32) for i in range(det.n_images)]
    img = [det.uv[det.image == i].astype(np.float32) for i in range(det.n_images)]
    K0, dist0 = lens.opencv()
    size = (lens.width_px, lens.height_px)
    rvecs: Any = []
    tvecs: Any = []
    if fit_lens:  # float32: OpenCV's calibration takes points so; only the start
        _, K, dist, rvecs, tvecs = cv2.calibrateCamera(
            obj, img, size, K0.copy(), dist0.copy(), flags=cv2.CALIB_USE_INTRINSIC_GUESS
        )
    else:
        K, dist = K0, dist0
        for i, (o, u) in enumerate(zip(obj, img, strict=True)):
            ok, rvec, tvec = cv2.solvePnP(o, u, K, dist, flags=cv2.SOLVEPNP_IPPE)
            if ok:
                ok, rvec, tvec = cv2.solvePnP(o, u, K, dist, rvec, tvec, True,
                                              flags=cv2.SOLVEPNP_ITERATIVE)  # fmt: skip
            if not ok:
                raise StageError(
                    f"camera fit: no pose of the target in image {i} (OpenCV solvePnP failed)",
                    expected="the target's points as the detector found them",
                    fix="check that the recorded target is the one in the images",
                )
            rvecs.append(rvec)
            tvecs.append(tvec)
    T = np.array([_pose(np.asarray(cv2.Rodrigues(r)[0], float), np.asarray(t, float))
                  for r, t in zip(rvecs, tvecs, strict=True)])  # fmt: skip
    n = design.n_joints
    base_from_flange = link_frames(design, det.q)[:, n]
    flange_from_base = invert_transform(base_from_flange)
    # calibrateRobotWorldHandEye solves cTw · wTb = cTg · gTb for wTb and cTg, "c" moving
    # with the gripper g, "w" fixed: eye-in-hand, c = the camera and w = the target;
    # eye-to-hand, c = the target and w = the camera.
    moving_from_fixed = T if setup == EYE_IN_HAND else invert_transform(T)
    R_wb, t_wb, R_cg, t_cg = cv2.calibrateRobotWorldHandEye(
        list(moving_from_fixed[:, :3, :3]), list(moving_from_fixed[:, :3, 3]),
        list(flange_from_base[:, :3, :3]), list(flange_from_base[:, :3, 3]),
        method=cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    )  # fmt: skip
    fixed_in_base = invert_transform(_pose(R_wb, t_wb))
    tool_in_flange = invert_transform(_pose(R_cg, t_cg))
    Kf, df = np.asarray(K, float), np.asarray(dist, float).ravel()
    k = np.concatenate([Kf[[0, 1, 0, 1], [0, 1, 2, 2]], df[:5]])
    return CameraStart(k, T, fixed_in_base, tool_in_flange)


def camera_model(
    det: Detections, design: SerialChain, start: CameraStart, setup: str
) -> tuple[ChainModel, Array]:
    """The chain model (tool point and rotation) and its start ``x`` (module docstring,
    step 3)."""
    n = design.n_joints
    sensor_from_base = invert_transform(start.fixed_in_base)
    F = sensor_from_base @ link_frames(design, det.q_signature)
    model = ChainModel(
        frames0=F[:n], prismatic=np.asarray(design.prismatic, bool),
        link=np.full(det.n_images, n, np.int64), theta=det.q - det.q_signature,
        point=np.zeros(det.n_images, np.int64), point_names=("tool",), tool_rotation=True,
    )  # fmt: skip
    # the tool body's measured pose per image, in the sensor frame
    T = start.camera_from_target if setup == EYE_TO_HAND else invert_transform(
        start.camera_from_target)  # fmt: skip
    x = np.zeros(model.n_params)
    x[model.point_slice(0)] = start_points(model, T[:, :3, 3])[0]
    rows = OrientationRows(np.arange(det.n_images), T[:, :3, :3], np.ones(det.n_images))
    x[model.rotation_slice] = start_rotation(model, x, rows)
    return model, x


def fit_camera(
    det: Detections,
    design: SerialChain,
    lens: Intrinsics,
    setup: str,
    intrinsics: str = "fitted",
    prior_sigma: Array | None = None,
    loss: str = "soft_l1",
    f_scale: float = 3.0,
) -> CameraFit:
    """The whole fit (module docstring). ``lens``: the stated lens (the start, the fixed
    values, or the prior's mean); ``prior_sigma`` (9,): the prior's σ (``intrinsics="prior"``)."""
    _check(det, setup, intrinsics)
    start = camera_start(det, design, lens, setup, fit_lens=intrinsics == "fitted")
    model, x_kin = camera_model(det, design, start, setup)
    k0 = lens.vector() if intrinsics != "fitted" else start.intrinsics
    keys = pa.table({"sweep": pa.array(np.full(det.n_images, POSES_SWEEP), pa.int32()),
                     "step": pa.array(np.arange(det.n_images), pa.int32()),
                     "target": ["tool"] * det.n_images})  # fmt: skip
    prior = lens.vector() if intrinsics == "prior" else None
    prior_s = None if prior is None else np.asarray(prior_sigma, float)
    block = CameraBlock(keys, det.image, det.local, det.uv, det.sigma_px, setup, k0, prior, prior_s)
    problem = Problem(model, block, loss, f_scale, fixed_block=intrinsics == "fixed")
    x_start = np.concatenate([x_kin, k0])
    solution = solve(problem, x_start)
    r = block.predict(model, solution.x[: model.n_params], solution.x[model.n_params :]) - det.uv
    rms = float(np.sqrt(np.mean(np.sum(r**2, axis=1))))
    names = (*model.param_names, *block.param_names)
    return CameraFit(model, block, solution, start, names, rms, x_start)
