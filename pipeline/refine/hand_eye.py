"""The camera fit of a session of flange poses: both hand-eye transforms and the lens.

A session whose robot reported the flange's pose at each image (its own forward
kinematics, no joint readings: industrial_calibration's and robot_cal_tools' data sets,
issue 40) cannot calibrate the arm. The flange poses replace the chain's forward
kinematics (:class:`FlangePoses`: a chain of no joints whose frame is the recorded flange
pose of each image), and the fit is the one of :func:`~pipeline.refine.camera_fit.fit_held`
(the peers' hand-eye problem, ``chain="design"``) with nothing of the arm to hold:

- the fixed body's pose in the base (the camera eye-to-hand, the target eye-in-hand):
  six parameters of the :class:`~pipeline.refine.camera_block.CameraBlock`
  (``fixed.rx, ry, rz``: a turn of its start orientation, rad; ``fixed.x, y, z`` cm);
- the body on the flange (the target eye-to-hand, the camera eye-in-hand) in the flange
  frame: its origin ``tool.x, y, z`` (cm) and rotation vector ``tool_rot.rx, ry, rz``;
- the nine intrinsics, fitted, held as given (``intrinsics="fixed"``) or with a prior.

The start is OpenCV's, as for a joint session
(:func:`~pipeline.refine.camera_start.start_from_flange`): the lens
(``cv2.calibrateCameraExtended`` when fitted), every view's PnP, then
``cv2.calibrateRobotWorldHandEye`` from the recorded flange poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.so3 import right_jacobian, rotation_from_vector, vector_from_rotation
from pipeline.optim.block import Array
from pipeline.refine.camera_fit import (
    CameraFit,
    Detections,
    camera_block,
    check_detections,
    fit_held,
)
from pipeline.refine.camera_start import start_from_flange
from pipeline.refine.kinematics import ChainModel
from pipeline.sensor.camera import Intrinsics


@dataclass(frozen=True, eq=False)
class FlangePoses(ChainModel):
    """A chain of no joints seen at the recorded flange poses ``flange`` (K, 4, 4, cm, in
    the base): the tool point ``p`` (``tool.x, y, z``, flange frame) is at
    ``R_i p + o_i``, the tool frame at ``R_i Exp(r)``; ``∂/∂p = R_i``,
    ``ω = R_i Exp(r) J_r(r) δr`` (as :class:`ChainModel`'s tool rotation)."""

    flange: Array = field(default_factory=lambda: np.zeros((0, 4, 4)))

    def positions(self, x: npt.ArrayLike) -> Array:
        p = np.asarray(x, float)[self.point_slice(0)]
        return np.asarray(self.flange[:, :3, :3] @ p + self.flange[:, :3, 3])

    def position_jacobian(self, x: npt.ArrayLike) -> Array:
        J = np.zeros((len(self.flange), 3, self.n_params))
        J[:, :, self.point_slice(0)] = self.flange[:, :3, :3]
        return J

    def tool_rotations(self, x: npt.ArrayLike) -> Array:
        return np.asarray(self.flange[:, :3, :3] @ self.tool_rotation_matrix(x))

    def tool_orientation_jacobian(self, x: npt.ArrayLike) -> Array:
        W = np.zeros((len(self.flange), 3, self.n_params))
        r = np.asarray(x, float)[self.rotation_slice]
        W[:, :, self.rotation_slice] = self.tool_rotations(x) @ right_jacobian(r)
        return W


def flange_model(flange_in_base: Array) -> FlangePoses:
    """The model of flange poses (m, 4, 4, cm): the tool point and rotation its only
    parameters (``x = [tool.x, y, z, tool_rot.rx, ry, rz]``)."""
    m = len(flange_in_base)
    none = np.zeros(m, np.int64)
    return FlangePoses(np.zeros((0, 4, 4)), np.zeros(0, bool), none, np.zeros((m, 0)), none,
                       ("tool",), True, flange=np.asarray(flange_in_base, float))  # fmt: skip


def flange_detections(
    image: npt.NDArray[np.int64], local: Array, uv: Array, sigma_px: Array, n_images: int
) -> Detections:
    """:class:`~pipeline.refine.camera_fit.Detections` of a session without joints."""
    return Detections(image, local, uv, sigma_px, np.zeros((n_images, 0)), np.zeros(0))


def fit_hand_eye(
    det: Detections,
    flange_in_base: Array,
    lens: Intrinsics,
    setup: str,
    intrinsics: str = "fitted",
    prior_sigma: Array | None = None,
    loss: str = "soft_l1",
    f_scale: float = 3.0,
) -> CameraFit:
    """Both hand-eye transforms and the lens from the pixels of ``det`` and the flange
    poses ``flange_in_base`` (m, 4, 4, cm) of its images (module docstring); ``lens``
    the stated lens (the start, the held values or the prior's mean)."""
    check_detections(det, setup, intrinsics)
    start = start_from_flange(det, flange_in_base, lens, setup, intrinsics == "fitted")
    model = flange_model(flange_in_base)
    x_kin = np.concatenate([start.tool_in_flange[:3, 3],
                            vector_from_rotation(start.tool_in_flange[:3, :3])])  # fmt: skip
    k0 = lens.vector() if intrinsics != "fitted" else start.intrinsics
    own = np.concatenate([np.zeros(3), start.fixed_in_base[:3, 3], k0])
    block = camera_block(det, setup, own, lens, intrinsics, prior_sigma, start.fixed_in_base)
    return fit_held(det, model, block, x_kin, start, intrinsics, loss, f_scale)


def tool_in_flange(fit: CameraFit) -> Array:
    """The body on the flange in the flange frame (4, 4, cm) of a :func:`fit_hand_eye`."""
    x = fit.solution.x
    T = np.eye(4)
    T[:3, :3] = rotation_from_vector(x[3:6])
    T[:3, 3] = x[:3]
    return T


def fixed_in_base(fit: CameraFit) -> Array:
    """The fixed body in the base (4, 4, cm) of a :func:`fit_hand_eye`."""
    T = fit.fixed_in_base
    assert T is not None  # a flange fit always has the fixed body's pose
    return T


def predicted_pixels(
    det: Detections, flange_in_base: Array, setup: str, fixed: Array, tool: Array,
    lens: Intrinsics,
) -> Array:  # fmt: skip
    """The pixels (D, 2) of ``det``'s points with the fixed body at ``fixed`` in the base,
    the flange's body at ``tool`` in the flange (4, 4, cm), seen through ``lens``."""
    model = flange_model(flange_in_base)
    x_kin = np.concatenate([tool[:3, 3], vector_from_rotation(tool[:3, :3])])
    own = np.concatenate([np.zeros(3), fixed[:3, 3], lens.vector()])
    block = camera_block(det, setup, own, lens, "fixed", None, fixed)
    return block.predict(model, x_kin, own)
