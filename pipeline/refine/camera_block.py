"""The measurement block of a camera: two whitened pixel residuals per detected point.

A camera session is a pose set whose "tool" is a rigid body on the flange, seen whole:
the target (eye-to-hand: the camera fixed in the cell is the sensor frame) or the camera
(eye-in-hand: the target fixed in the cell is the sensor frame). The chain
(:class:`~pipeline.refine.kinematics.ChainModel` with ``tool_rotation``) gives that body's
pose at image ``i``: its origin ``t_i`` (the tool point) and its rotation ``R_i`` (the
tool frame). A target point ``c`` (its local coordinates, cm) is then seen in the camera
at

- eye-to-hand: ``P = t_i + R_i c``;  ``∂P/∂t = I``,  ``∂P/∂ω = −[R_i c]×``
- eye-in-hand: ``P = R_iᵀ (c − t_i)``;  ``∂P/∂t = −R_iᵀ``,  ``∂P/∂ω = R_iᵀ [c − t_i]×``

(``δR = [ω]× R``), projected by the lens (:func:`pipeline.sensor.camera.project`), and the
residual is ``r = (π(P; k) − m) / σ`` with ``m`` the detected pixel and ``σ`` its stated
noise (px). The intrinsics ``k`` (OpenCV's ``fx, fy, cx, cy, k1, k2, p1, p2, k3``) are the
block's own parameters; with a prior (``prior_sigma``, a ``cv2.calibrateCamera`` result
and its σ) nine more rows ``(k − k_prior) / σ_prior``.

With ``fixed_start`` the sensor frame is instead the robot's base and the fixed body's
pose in it, ``(R_f, t_f)`` with ``R_f = Exp(ρ) R_f⁰``, is six more parameters of the block
(``fixed.rx, ry, rz`` rad, ``fixed.x, y, z`` cm, before the intrinsics): the hand-eye
problem of the peers when the chain is held at its design (:mod:`pipeline.refine.camera_fit`,
``chain="design"``). A point ``p_w`` in the base is then seen at

- eye-to-hand: ``p_w = t_i + R_i c``, ``P = R_fᵀ (p_w − t_f)``;
  ``∂P/∂ω_f = R_fᵀ [p_w − t_f]×``, ``∂P/∂t_f = −R_fᵀ``
- eye-in-hand: ``p_w = R_f c + t_f``, ``P = R_iᵀ (p_w − t_i)``;
  ``∂p_w/∂ω_f = −[R_f c]×``, ``∂p_w/∂t_f = I``

with ``δR_f = [ω_f]× R_f``, ``ω_f = J_l(ρ) δρ`` (the left Jacobian of SO(3), ``J_r(−ρ)``).

The rows depend on the tool point's position (``pos``, ``d_p``) and on the tool's
orientation (``d_theta = ∂r/∂P · ∂P/∂ω · Ω``, ``Ω`` the tool frame's ``ω`` per kinematic
parameter, :meth:`~pipeline.refine.kinematics.ChainModel.tool_orientation_jacobian`), so
the block linearizes with the model (:meth:`CameraBlock.linearize_pose`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from pipeline.kinematics.so3 import right_jacobian, rotation_from_vector
from pipeline.optim.block import Array, Linearization
from pipeline.refine.kinematics import ChainModel
from pipeline.sensor.camera import INTRINSIC_NAMES, INTRINSIC_UNITS, project_with_jacobians

EYE_TO_HAND, EYE_IN_HAND = "eye-to-hand", "eye-in-hand"


def _skew(v: Array) -> Array:
    """``[v]×`` (..., 3, 3) of vectors (..., 3)."""
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def camera_points(setup: str, t: Array, R: Array, local: Array) -> tuple[Array, Array, Array]:
    """Points ``P`` (D, 3) in the camera, ``∂P/∂t`` (D, 3, 3) and ``∂P/∂ω`` (D, 3, 3), of
    target points ``local`` (D, 3) with the tool body at ``t`` (D, 3), ``R`` (D, 3, 3)."""
    if setup == EYE_TO_HAND:
        Rc = np.einsum("dij,dj->di", R, local)
        return t + Rc, np.broadcast_to(np.eye(3), R.shape), -_skew(Rc)
    d = local - t
    Rt = np.swapaxes(R, 1, 2)
    return np.einsum("dij,dj->di", Rt, d), -Rt, Rt @ _skew(d)


FIXED_NAMES = ("fixed.rx", "fixed.ry", "fixed.rz", "fixed.x", "fixed.y", "fixed.z")
FIXED_UNITS = ("rad", "rad", "rad", "cm", "cm", "cm")


@dataclass(eq=False)  # not frozen: MeasurementBlock declares settable attributes
class CameraBlock:
    """A :class:`~pipeline.optim.block.MeasurementBlock` of pixel detections.

    Attributes
    ----------
    keys : pyarrow.Table
        One row per image (sweep, step, target ``tool``): the model's observations.
    image : ndarray of int, shape (D,)
        The image (row of ``keys``) of each detection.
    local : ndarray, shape (D, 3)
        The detected target point in the target's frame (cm).
    measured : ndarray, shape (D, 2)
        Its pixel ``(u, v)``.
    sigma_px : ndarray, shape (D,)
        σ of ``u`` and of ``v`` (px).
    setup : str
        ``eye-to-hand`` or ``eye-in-hand`` (module docstring).
    x0 : ndarray, shape (9,) or (15,)
        The start of the block's parameters: ``[ρ, t_f]`` with ``fixed_start``, then the
        intrinsics.
    prior, prior_sigma : ndarray, shape (9,), optional
        A prior on the intrinsics and its σ (inf: no prior on that one).
    fixed_start : ndarray, shape (4, 4), optional
        ``R_f⁰`` (its rotation) of the fixed body in the base; None: the sensor frame is
        the fixed body's (module docstring).
    """

    keys: pa.Table
    image: npt.NDArray[np.int64]
    local: Array
    measured: Array
    sigma_px: Array
    setup: str
    x0: Array
    prior: Array | None = None
    prior_sigma: Array | None = None
    fixed_start: Array | None = None
    param_names: tuple[str, ...] = tuple(f"camera.{n}" for n in INTRINSIC_NAMES)
    param_units: tuple[str, ...] = INTRINSIC_UNITS

    def __post_init__(self) -> None:
        if self.fixed_start is not None:
            self.param_names = (*FIXED_NAMES, *self.param_names[-9:])
            self.param_units = (*FIXED_UNITS, *self.param_units[-9:])

    def linearize(self, p: Array, x: Array) -> Linearization:
        """Not used: pixels depend on the tool's orientation too (:meth:`linearize_pose`)."""
        raise TypeError("a camera block linearizes with the model: linearize_pose")

    def fixed_pose(self, x: Array) -> Array:
        """The fixed body's pose in the base (4, 4) at the block's parameters ``x``."""
        T = np.eye(4)
        if self.fixed_start is not None:
            T[:3, :3] = rotation_from_vector(x[:3]) @ self.fixed_start[:3, :3]
            T[:3, 3] = x[3:6]
        return T

    def points_in_camera(
        self, model: ChainModel, x_kin: Array, x: Array
    ) -> tuple[Array, Array, Array, Array | None, Array | None]:
        """``P`` (D, 3), ``∂P/∂t``, ``∂P/∂ω`` (D, 3, 3) and, with a fixed pose, ``∂P/∂ρ``
        and ``∂P/∂t_f`` (D, 3, 3) (module docstring)."""
        t, R = model.positions(x_kin)[self.image], model.tool_rotations(x_kin)[self.image]
        if self.fixed_start is None:
            P, dP_dt, dP_dw = camera_points(self.setup, t, R, self.local)
            return P, dP_dt, dP_dw, None, None
        F = self.fixed_pose(x)
        Rf, tf = F[:3, :3], F[:3, 3]
        J_l = right_jacobian(-x[:3])  # ω_f = J_l(ρ) δρ
        if self.setup == EYE_TO_HAND:
            p_w, dw_dt, dw_dw = camera_points(EYE_TO_HAND, t, R, self.local)
            P = (p_w - tf) @ Rf  # R_fᵀ (p_w − t_f)
            return (P, Rf.T @ dw_dt, Rf.T @ dw_dw, Rf.T @ _skew(p_w - tf) @ J_l,
                    np.broadcast_to(-Rf.T, dw_dt.shape))  # fmt: skip
        p_w = self.local @ Rf.T + tf
        P, dP_dt, dP_dw = camera_points(EYE_IN_HAND, t, R, p_w)
        Rt = np.swapaxes(R, 1, 2)
        return P, dP_dt, dP_dw, Rt @ (-_skew(p_w - tf)) @ J_l, Rt

    def predict(self, model: ChainModel, x_kin: Array, x: Array) -> Array:
        """Predicted pixels (D, 2) at kinematic parameters ``x_kin``, block parameters ``x``."""
        return project_with_jacobians(self.points_in_camera(model, x_kin, x)[0], x[-9:])[0]

    def linearize_pose(self, model: ChainModel, x_kin: Array, x: Array) -> Linearization:
        """Residuals and derivatives at ``x_kin`` (the chain) and ``x`` (the block's)."""
        W = model.tool_orientation_jacobian(x_kin)  # (K, 3, n_kin)
        img = self.image
        P, dP_dt, dP_dw, dP_drho, dP_dtf = self.points_in_camera(model, x_kin, x)
        uv, J_p, J_k = project_with_jacobians(P, x[-9:])
        s = self.sigma_px[:, None, None]
        r = (uv - self.measured) / self.sigma_px[:, None]
        d_p = (J_p @ dP_dt) / s  # (D, 2, 3)
        d_theta = ((J_p @ dP_dw) / s) @ W[img]  # (D, 2, n_kin)
        d_x = J_k / s  # (D, 2, 9)
        if dP_drho is not None and dP_dtf is not None:
            d_x = np.concatenate([J_p @ dP_drho / s, J_p @ dP_dtf / s, d_x], axis=2)
        D, n_kin, n_x = len(img), W.shape[2], d_x.shape[2]
        lin_r, pos = r.reshape(-1), np.repeat(img, 2)
        d_p, d_theta = d_p.reshape(2 * D, 3), d_theta.reshape(2 * D, n_kin)
        d_x = d_x.reshape(2 * D, n_x)
        if self.prior is not None and self.prior_sigma is not None:
            has = np.isfinite(self.prior_sigma)
            m = int(has.sum())
            rows = np.zeros((m, n_x))
            rows[:, n_x - 9 :] = np.diag(1.0 / self.prior_sigma)[has]
            lin_r = np.concatenate([lin_r, ((x[-9:] - self.prior) / self.prior_sigma)[has]])
            pos = np.concatenate([pos, np.full(m, -1)])
            d_p = np.vstack([d_p, np.zeros((m, 3))])
            d_theta = np.vstack([d_theta, np.zeros((m, n_kin))])
            d_x = np.vstack([d_x, rows])
        return Linearization(r=lin_r, pos=pos.astype(np.int64), d_p=d_p, d_x=d_x,
                             d_theta=d_theta)  # fmt: skip
