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

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.kinematics.transforms import invert_transform
from pipeline.optim.block import Array
from pipeline.refine.camera_block import EYE_IN_HAND, EYE_TO_HAND, CameraBlock
from pipeline.refine.camera_readings import (
    image_pose_variance,
    pose_basis,
    pose_covariance,
    reading_covariance,
    reading_jacobian,
    reading_pose_share,
)
from pipeline.refine.camera_start import CameraStart, camera_start
from pipeline.refine.identifiability import (
    Identifiability,
    analyse,
    fit_identifiable,
    tolerance_scale,
)
from pipeline.refine.kinematics import ChainModel, start_points
from pipeline.refine.orientation import OrientationRows, start_rotation
from pipeline.refine.solve import Problem, Solution, residuals_and_jacobian, solve
from pipeline.sensor.camera import Intrinsics, project_with_jacobians
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
class CameraFit:
    """The fit: its model and solution, the start, names, and the rms pixel residual."""

    model: ChainModel
    block: CameraBlock
    solution: Solution
    start: CameraStart
    names: tuple[str, ...]
    rms_px: float
    x_start: Array  # the closed-form start of every parameter
    identifiability: Identifiability  # what the pixels could identify; the rest held
    block_fixed: bool = False  # the lens held as given (not the data's verdict)
    #: ``w²`` (px² per coordinate) of the independent pixels and ``τ²`` (px²) of an error
    #: shared by each image's points as a rigid motion of the target, beyond the readings'
    #: (refine/camera_readings.py, image_pose_variance), both in the covariance; 0: none
    independent_px2: float = 0.0
    shared_px2: float = 0.0

    @property
    def intrinsics(self) -> Array:
        return self.solution.x[-9:]

    @property
    def fixed_in_base(self) -> Array | None:
        """The fixed body in the design's base (4, 4) of a fit with the chain held at its
        design; None otherwise (the sensor frame is then the fixed body's)."""
        if self.block.fixed_start is None:
            return None
        return self.block.fixed_pose(self.solution.x[self.model.n_params :])

    def image_residuals(self) -> tuple[Array, Array, Array]:
        """Per image: detected points (m,), rms and largest reprojection error (m,), px."""
        x = self.solution.x
        n = self.model.n_params
        r = np.linalg.norm(self.block.predict(self.model, x[:n], x[n:]) - self.block.measured,
                           axis=1)  # fmt: skip
        img, m = self.block.image, len(self.model.theta)
        count = np.bincount(img, minlength=m)
        rms = np.sqrt(np.bincount(img, r**2, m) / np.maximum(count, 1))
        worst = np.zeros(m)
        np.maximum.at(worst, img, r)
        return count.astype(float), np.asarray(rms, float), worst

    def tool_poses(self, q: Array, q_signature: Array) -> Array:
        """The tool body's pose in the sensor frame (m, 4, 4) at joint values ``q`` (m, n)."""
        return tool_poses(self.model, self.solution.x[: self.model.n_params], q, q_signature)

    def tool_covariances(self, q: Array, q_signature: Array, bound: bool = False) -> Array:
        """Covariance (m, 3, 3) of the tool point at joint values ``q`` (m, n), cm²: the
        fit's (Gauss-Newton, scaled by χ²/dof) propagated, ``J Σ_θ Jᵀ`` with ``Σ_θ`` the
        kinematic block (the intrinsics marginalised). ``bound``: unscaled, the stated
        pixel noise taken as true: the Cramér-Rao bound of the session at the solution."""
        s = self.solution
        n = self.model.n_params
        cov = s.covariance[:n, :n] / (s.noise_scale**2 if bound else 1.0)
        J = observing(self.model, q, q_signature).position_jacobian(s.x[:n])
        return np.asarray(J @ cov @ np.swapaxes(J, 1, 2))


def observing(model: ChainModel, q: Array, q_signature: Array) -> ChainModel:
    """``model`` observing the tool at joint values ``q`` (m, n), ``q̄^s`` ``q_signature``."""
    m = len(q)
    link, point = np.full(m, model.n_joints), np.zeros(m, np.int64)
    return ChainModel(model.frames0, model.prismatic, link, q - q_signature, point,
                      model.point_names, True)  # fmt: skip


def tool_poses(model: ChainModel, x_kin: Array, q: Array, q_signature: Array) -> Array:
    """The tool body's pose in the sensor frame (m, 4, 4) at joint values ``q`` (m, n) of
    the chain ``model`` at its parameters ``x_kin``."""
    at = observing(model, q, q_signature)
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    T[:, :3, :3], T[:, :3, 3] = at.tool_rotations(x_kin), at.positions(x_kin)
    return T


def held_line(fit: CameraFit, sigma_px: float) -> str | None:
    """One line naming the parameters the images could not identify (held at their start)
    and what to measure so that they can be, or None when every one was identified."""
    ident = fit.identifiability
    held = np.flatnonzero(ident.held)
    held = held[held < fit.model.n_params] if fit.block_fixed else held
    if not len(held):
        return None
    names = [fit.names[k] for k in held]
    heads = {n.split(".")[0] for n in names}
    todo = []
    joints = sorted(h for h in heads if h.startswith("joint"))
    if joints:
        todo.append(f"move {', '.join(joints)} between images (each over tens of degrees)")
    if heads & {"tool", "tool_rot"}:
        todo.append("turn the wrist between images so that the flange's body is seen from "
                    "several sides")  # fmt: skip
    lens = {n.split(".")[1] for n in names if n.startswith("camera.")}
    if lens & {"fx", "fy"}:
        todo.append("tilt the target against the camera (30° or more) and vary its distance: "
                    "one target orientation leaves the focal length and the distance "
                    "correlated")  # fmt: skip
    if lens & {"cx", "cy", "k1", "k2", "p1", "p2", "k3"}:
        todo.append("put the target in every part of the image, the corners too")
    return (
        f"camera fit: {len(held)} of {len(fit.names)} parameters held at their start, the "
        f"images cannot tell them from the {sigma_px:g} px noise: {', '.join(names)}; "
        f"measure more images: {'; '.join(todo)}"
    )


def check_detections(det: Detections, setup: str, intrinsics: str) -> None:
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


def camera_model(
    det: Detections, design: SerialChain, start: CameraStart, setup: str, chain: str = "fitted"
) -> tuple[ChainModel, Array]:
    """The chain model (tool point and rotation) and its start ``x`` (module docstring,
    step 3); ``chain="design"``: in the design's base frame (the fixed body then a
    parameter of the block)."""
    n = design.n_joints
    base = np.eye(4) if chain == "design" else invert_transform(start.fixed_in_base)
    F = base @ link_frames(design, det.q_signature)
    model = ChainModel(
        frames0=F[:n], prismatic=np.asarray(design.prismatic, bool),
        link=np.full(det.n_images, n, np.int64), theta=det.q - det.q_signature,
        point=np.zeros(det.n_images, np.int64), point_names=("tool",), tool_rotation=True,
    )  # fmt: skip
    # the tool body's measured pose per image, in the model's frame
    T = start.camera_from_target if setup == EYE_TO_HAND else invert_transform(
        start.camera_from_target)  # fmt: skip
    if chain == "design":
        T = start.fixed_in_base @ T
    x = np.zeros(model.n_params)
    x[model.point_slice(0)] = start_points(model, T[:, :3, 3])[0]  # NaN rows: no pose
    seen = np.flatnonzero(np.isfinite(T).all(axis=(1, 2)))
    rows = OrientationRows(seen, T[seen, :3, :3], np.ones(len(seen)))
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
    chain: str = "fitted",
    reading_sigma: Array | None = None,
) -> CameraFit:
    """The whole fit (module docstring). ``lens``: the stated lens (the start, the fixed
    values, or the prior's mean); ``prior_sigma`` (9,): the prior's σ (``intrinsics="prior"``).
    ``chain="design"``: the hand-eye problem of the peers, the chain held at its design
    (the sensor frame is then the design's base, the fixed body's pose six parameters of
    the block: :class:`~pipeline.refine.camera_block.CameraBlock`). ``reading_sigma``
    (n,): the joint readings' σ (rad / cm; the encoders' rounding), whose share of the
    covariance the pixels' weights miss (:mod:`pipeline.refine.camera_readings`)."""
    check_detections(det, setup, intrinsics)
    start = camera_start(det, design, lens, setup, fit_lens=intrinsics == "fitted")
    model, x_kin = camera_model(det, design, start, setup, chain)
    k0 = lens.vector() if intrinsics != "fitted" else start.intrinsics
    if chain == "design":
        own = np.concatenate([np.zeros(3), start.fixed_in_base[:3, 3], k0])
        block = camera_block(det, setup, own, lens, intrinsics, prior_sigma, start.fixed_in_base)
        return fit_held(det, model, block, x_kin, start, intrinsics, loss, f_scale,
                        reading_sigma)  # fmt: skip
    block = camera_block(det, setup, k0, lens, intrinsics, prior_sigma)
    x_start = np.concatenate([x_kin, k0])
    problem = Problem(model, block, loss, f_scale, fixed_block=intrinsics == "fixed")
    units = (*model.param_units, *block.param_units)
    solution, ident = fit_identifiable(problem, x_start, units, True, len(det.image))
    if ident.held.any() and not ident.held[: model.n_params].any():  # only lens terms held
        solution, ident = fit_identifiable(
            problem, x_start, units, True, len(det.image), solution.x, solution.f_scale,
            tolerances(units, start, block),
        )  # fmt: skip
    return _result(problem, block, det, solution, start, x_start, ident, intrinsics,
                   reading_sigma)  # fmt: skip


def camera_block(
    det: Detections, setup: str, own: Array, lens: Intrinsics, intrinsics: str,
    prior_sigma: Array | None, fixed: Array | None = None,
) -> CameraBlock:  # fmt: skip
    """The pixel block of ``det`` started at ``own``; with ``intrinsics="prior"`` the
    stated ``lens`` its prior (σ ``prior_sigma``); ``fixed``: the fixed body's start pose
    in the base (:class:`~pipeline.refine.camera_block.CameraBlock`)."""
    keys = pa.table({"sweep": pa.array(np.full(det.n_images, POSES_SWEEP), pa.int32()),
                     "step": pa.array(np.arange(det.n_images), pa.int32()),
                     "target": ["tool"] * det.n_images})  # fmt: skip
    prior = lens.vector() if intrinsics == "prior" else None
    prior_s = None if prior is None else np.asarray(prior_sigma, float)
    return CameraBlock(keys, det.image, det.local, det.uv, det.sigma_px, setup, own, prior,
                       prior_s, fixed)  # fmt: skip


def tolerances(units: tuple[str, ...], start: CameraStart, block: CameraBlock) -> Array:
    """Each parameter's tolerance in the identifiability analysis: the design's for the
    chain and the hand-eye (:func:`~pipeline.refine.identifiability.tolerance_scale`);
    for the lens the larger of that and the σ its start is known to: OpenCV's
    calibration's (the lens fitted, started there) or the prior's.

    :func:`fit_camera` analyses with these when the design's tolerances held lens terms
    and nothing of the chain or the hand-eye: a lens term the images determine better
    than its start is then fitted, not held at a start worse than the fit (a narrow
    view, f 2,000 px, noiseless rendered images: ``cx`` held 1.4 px off at OpenCV's, the
    sensor frame turned 0.04° and the tool point 1.39 mm off against 0.26 mm predicted;
    fitted: 0.36 mm, predicted 0.39 mm; docs/camera.md). With parameters of the chain
    held the design's tolerances stay: what the held ones leave goes into a lens term
    fitted beyond them (one target orientation, ``tests/test_camera_fit.py``: the focal
    length fitted 918 ± 2.9 px against the true 991)."""
    tol = tolerance_scale(units)
    known = start.intrinsics_sigma if block.prior_sigma is None else block.prior_sigma
    if known is not None:
        k = np.asarray(known, float)
        tol[-9:] = np.where(np.isfinite(k), np.maximum(tol[-9:], k), tol[-9:])
    return tol


def fit_held(
    det: Detections, model: ChainModel, block: CameraBlock, x_kin: Array, start: CameraStart,
    intrinsics: str, loss: str, f_scale: float, reading_sigma: Array | None = None,
) -> CameraFit:  # fmt: skip
    """The fit with the chain's axes held (at the design, or none: a session of flange
    poses, :mod:`pipeline.refine.hand_eye`), the fixed body's pose six parameters of the
    block, the lens held by mask (``intrinsics="fixed"``); ``reading_sigma`` as
    :func:`fit_camera`'s."""
    x_start = np.concatenate([x_kin, block.x0])
    held = np.zeros(len(x_start), bool)
    held[: model.n_axis_params] = True
    held[len(x_start) - 9 :] = intrinsics == "fixed"
    problem = Problem(model, block, loss, f_scale, held=held)
    solution = solve(problem, x_start)
    units = (*model.param_units, *block.param_units)
    J = residuals_and_jacobian(problem, solution.x)[1]
    ident = analyse(J, units, True, len(det.image), held, tolerances(units, start, block))
    return _result(problem, block, det, solution, start, x_start, ident, intrinsics,
                   reading_sigma, J)  # fmt: skip


def _with_shared(
    problem: Problem, block: CameraBlock, solution: Solution, reading_sigma: Array | None,
    r_px: Array, P: Array, J_p: Array, J: Array | None,
) -> tuple[Solution, float, float]:  # fmt: skip
    """``solution`` with the errors an image's points share added to its covariance: the
    joint readings' rounding (:func:`~pipeline.refine.camera_readings.reading_covariance`,
    with ``reading_sigma``) and a rigid motion of the target in the camera per image
    beyond it, when the residuals ``r_px`` (D, 2) show one along the images' pose bases
    (of the points ``P`` in the camera and their pixels' derivatives ``J_p``:
    :func:`~pipeline.refine.camera_readings.image_pose_variance`); and that error's
    ``w²``, ``τ²`` (px²; 0, 0: none). With one, the independent pixels' share is scaled
    by ``w²`` instead of the fit's χ²/dof, which holds the shared error too. As it is
    without noise (noiseless: 0, as the rest). ``J``: the whitened Jacobian at the
    solution when formed already."""
    if not solution.noise_scale > 0:
        return solution, 0.0, 0.0
    s2 = solution.noise_scale**2
    model, x = problem.model, solution.x
    J = residuals_and_jacobian(problem, x)[1] if J is None else J
    unscaled = solution.covariance / s2
    Q = pose_basis(block.image, P, J_p)
    known, readings = None, np.zeros_like(unscaled)
    if reading_sigma is not None:
        G = reading_jacobian(block, model, x)
        readings = reading_covariance(block, model, x, J, unscaled, reading_sigma, G)
        known = reading_pose_share(block, G, reading_sigma, Q)
    free = np.diag(unscaled) > 0  # the fitted parameters: held ones absorb nothing
    w2, tau2 = image_pose_variance(block.image, r_px, Q, J[:, free], known)
    scale = w2 / float(np.mean(block.sigma_px**2)) if tau2 > 0 else s2
    cov = scale * (unscaled + readings)
    if tau2 > 0:
        cov += pose_covariance(block, J, unscaled, tau2, Q)
    return replace(solution, covariance=cov), w2, tau2


def _result(
    problem: Problem, block: CameraBlock, det: Detections, solution: Solution,
    start: CameraStart, x_start: Array, ident: Identifiability, intrinsics: str,
    reading_sigma: Array | None, J: Array | None = None,
) -> CameraFit:  # fmt: skip
    """The fit of ``solution``: its pixels projected once, for the rms and the errors the
    images' points share (:func:`_with_shared`, ``J`` as its)."""
    model, n = problem.model, problem.model.n_params
    P = block.points_in_camera(model, solution.x[:n], solution.x[n:])[0]
    uv, J_p, _ = project_with_jacobians(P, solution.x[-9:])
    r = uv - det.uv
    solution, w2, tau2 = _with_shared(problem, block, solution, reading_sigma, r, P, J_p, J)
    rms = float(np.sqrt(np.mean(np.sum(r**2, axis=1))))
    names = (*model.param_names, *block.param_names)
    return CameraFit(model, block, solution, start, names, rms, x_start, ident,
                     intrinsics == "fixed", w2, tau2)  # fmt: skip
