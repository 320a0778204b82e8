"""The closed-form start of a camera fit, as the peers do it (OpenCV throughout).

1. The lens and every image's target pose. With the intrinsics fitted:
   ``cv2.calibrateCameraExtended`` (Zhang's method, the stated lens as its guess); a view
   whose own reprojection error is an outlier (above :data:`OUTLIER_VIEW` times the
   median and :data:`MIN_VIEW_PX`) is left out and the lens calibrated again, up to
   :data:`CALIBRATION_ROUNDS` times: one view of 8 points near the image's edge made
   the whole calibration diverge (fx 1000 instead of 987, no distortion, 7 px rms; a
   Puma eye-in-hand session of 150 images, seed 3). Then ``cv2.solvePnP`` of every image
   with that lens (IPPE, refined iteratively). With the intrinsics given, the PnP alone.
2. Both hand-eye transforms, ``cv2.calibrateRobotWorldHandEye`` from the design's flange
   poses at the readings and the per-image poses of the views that reproject within
   the outlier bound, by Shah's and by Li's method (``method=`` by keyword: a positional
   method is silently Tsai, opencv #27625); the one whose transforms agree best with
   every view (``cTw · wTb = cTg · gTb``, the median translation misfit) is the start.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.errors import StageError
from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.kinematics.transforms import invert_transform
from pipeline.optim.block import Array
from pipeline.refine.camera_block import EYE_IN_HAND
from pipeline.sensor.camera import Intrinsics

#: A view reprojecting worse than this many times the median view (and than
#: :data:`MIN_VIEW_PX`) is an outlier of the start (the fit itself uses every point).
OUTLIER_VIEW = 5.0
MIN_VIEW_PX = 1.0
CALIBRATION_ROUNDS = 3
#: Views with a pose the hand-eye needs at least (OpenCV asks for 3; a few more).
MIN_VIEWS = 5


@dataclass(frozen=True)
class CameraStart:
    """The closed-form start: the lens, the target's pose in the camera per image (m, 4, 4),
    OpenCV's hand-eye (``fixed_in_base``: camera or target in the design's base frame,
    ``tool_in_flange``: target or camera in the design's last link frame, 4 × 4, cm), the
    hand-eye method chosen and the views the start used."""

    intrinsics: Array
    camera_from_target: Array
    fixed_in_base: Array
    tool_in_flange: Array
    method: str = ""
    views: int = 0
    #: σ of ``intrinsics`` (9,): OpenCV's calibration's (its ``stdDeviationsIntrinsics``,
    #: at its own scatter) at the detections' stated σ when that is larger, as the fit's
    #: identifiability whitens; None when the lens was given, not calibrated here
    intrinsics_sigma: Array | None = None


def _pose(R: Any, t: Any) -> Array:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = np.asarray(R, float), np.ravel(np.asarray(t, float))
    return T


def _outliers(errors: Array) -> np.ndarray:
    """Whether each view's reprojection error (px) is an outlier (module docstring)."""
    bound = max(OUTLIER_VIEW * float(np.median(errors)), MIN_VIEW_PX)
    return np.asarray(errors > bound, dtype=bool)


def _lens(obj: list[Any], img: list[Any], lens: Intrinsics) -> tuple[Any, Any, Array, float]:
    """OpenCV's calibration of the views, the outlier views left out (module docstring),
    the σ it states for its nine intrinsics (OpenCV's order, armsig's) and the scatter
    (px per coordinate) they are at: its rms reprojection error (px per point) over √2."""
    import cv2

    K0, dist0 = lens.opencv()
    use = np.arange(len(obj))
    K: Any = K0
    dist: Any = dist0
    sigma, scatter = np.full(9, np.nan), float("nan")
    for _ in range(CALIBRATION_ROUNDS):  # float32: OpenCV's calibration takes points so
        out = cv2.calibrateCameraExtended(
            [obj[i] for i in use], [img[i] for i in use], (lens.width_px, lens.height_px),
            K0.copy(), dist0.copy(), flags=cv2.CALIB_USE_INTRINSIC_GUESS,
        )  # fmt: skip
        K, dist, per_view = out[1], out[2], np.ravel(np.asarray(out[7], float))
        sigma, scatter = np.ravel(np.asarray(out[5], float))[:9], float(out[0]) / np.sqrt(2)
        bad = _outliers(per_view)
        if not bad.any():
            break
        use = use[~bad]
    return K, dist, sigma, scatter


def _pnp(o: Any, u: Any, K: Any, dist: Any) -> tuple[Array, float]:
    """The target's pose in the camera from one view, and its rms reprojection (px); NaN
    where OpenCV finds none (points on one line: the view is left out of the start)."""
    import cv2

    ok, rvec, tvec = cv2.solvePnP(o, u, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if ok:
        ok, rvec, tvec = cv2.solvePnP(o, u, K, dist, rvec, tvec, True,
                                      flags=cv2.SOLVEPNP_ITERATIVE)  # fmt: skip
    if not ok:
        return np.full((4, 4), np.nan), float("nan")
    back, _ = cv2.projectPoints(o, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((back[:, 0] - u) ** 2, axis=1))))
    return _pose(cv2.Rodrigues(rvec)[0], tvec), rms


def _hand_eye(moving_from_fixed: Array, flange_from_base: Array) -> tuple[Array, Array, str]:
    """(``wTb``, ``cTg``, method) of ``cTw · wTb = cTg · gTb`` (module docstring)."""
    import cv2

    best: tuple[float, Array, Array, str] | None = None
    for name in ("SHAH", "LI"):
        R_wb, t_wb, R_cg, t_cg = cv2.calibrateRobotWorldHandEye(
            list(moving_from_fixed[:, :3, :3]), list(moving_from_fixed[:, :3, 3]),
            list(flange_from_base[:, :3, :3]), list(flange_from_base[:, :3, 3]),
            method=getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{name}"),
        )  # fmt: skip
        wTb, cTg = _pose(R_wb, t_wb), _pose(R_cg, t_cg)
        misfit = (moving_from_fixed @ wTb)[:, :3, 3] - (cTg @ flange_from_base)[:, :3, 3]
        m = float(np.median(np.linalg.norm(misfit, axis=1)))
        if np.isfinite(m) and (best is None or m < best[0]):
            best = (m, wTb, cTg, name)
    if best is None:
        raise StageError(
            "camera fit: OpenCV's hand-eye found no finite solution",
            expected="images at poses that turn the flange about two axes at least",
            fix="record more images, turning every joint between them",
        )
    return best[1], best[2], best[3]


def camera_start(
    det: Any, design: SerialChain, lens: Intrinsics, setup: str, fit_lens: bool
) -> CameraStart:
    """The closed-form start of :class:`~pipeline.refine.camera_fit.Detections` ``det``
    (module docstring), the flange poses the design's at the readings."""
    return start_from_flange(det, link_frames(design, det.q)[:, design.n_joints], lens, setup,
                             fit_lens)  # fmt: skip


def start_from_flange(
    det: Any, base_from_flange: Array, lens: Intrinsics, setup: str, fit_lens: bool
) -> CameraStart:
    """The closed-form start of ``det`` with the flange in the base ``base_from_flange``
    (m, 4, 4, cm) at every image: the design's at the readings, or the robot's own
    (a session of flange poses, :mod:`pipeline.refine.hand_eye`)."""
    obj = [det.local[det.image == i].astype(np.float32) for i in range(det.n_images)]
    img = [det.uv[det.image == i].astype(np.float32) for i in range(det.n_images)]
    sigma = None
    if fit_lens:
        K, dist, at, scatter = _lens(obj, img, lens)
        stated = float(np.median(det.sigma_px))
        sigma = at * max(stated, scatter) / scatter if scatter > 0 else np.full(9, np.nan)
    else:
        K, dist = lens.opencv()
    views = [_pnp(o, u, K, dist) for o, u in zip(obj, img, strict=True)]
    T = np.array([v[0] for v in views])
    errors = np.array([v[1] for v in views])
    found = np.isfinite(errors)
    if found.sum() < MIN_VIEWS:
        raise StageError(
            f"camera fit: OpenCV finds the target's pose in {int(found.sum())} of "
            f"{len(views)} images",
            expected=f"at least {MIN_VIEWS} images whose points are not on one line",
            fix="record images that show the target's points in two directions",
        )
    good = found.copy()
    good[found] = ~_outliers(errors[found])
    # calibrateRobotWorldHandEye solves cTw · wTb = cTg · gTb for wTb and cTg, "c" moving
    # with the gripper g, "w" fixed: eye-in-hand, c = the camera and w = the target;
    # eye-to-hand, c = the target and w = the camera.
    moving_from_fixed = T if setup == EYE_IN_HAND else invert_transform(T)
    wTb, cTg, method = _hand_eye(moving_from_fixed[good], invert_transform(base_from_flange[good]))
    Kf, df = np.asarray(K, float), np.asarray(dist, float).ravel()
    k = np.concatenate([Kf[[0, 1, 0, 1], [0, 1, 2, 2]], df[:5]])
    return CameraStart(k, T, invert_transform(wTb), invert_transform(cTg), method, int(good.sum()),
                       sigma)  # fmt: skip
