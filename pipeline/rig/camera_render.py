"""Render a camera image of a target (issue 40): the board drawn at a known pose through a
pinhole camera, with blur and noise, so that detectors are tested against the truth.

The board is drawn flat (:func:`board_image`: ``px_per_cm`` pixels per cm, ``margin_px``
of white around it) and warped by the homography of the pose into an image
``SUPERSAMPLE`` times finer than the camera's, blurred there (σ in camera pixels), then
averaged down to the camera's pixels (``cv2.INTER_AREA``: each pixel integrates its area,
as a sensor's pixel does) and given Gaussian grey-level noise. Pixel centres follow
OpenCV's convention: the top-left pixel's centre is (0, 0), in the board image as in the
camera's. The lens is undistorted (a homography maps a plane only through a pinhole).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.target import Target

#: Each camera pixel is rendered as SUPERSAMPLE × SUPERSAMPLE samples, then averaged.
SUPERSAMPLE = 4
WHITE, BLACK = 235, 20  # grey levels of the board's paper and ink (no clipping of noise)


def board_image(target: Target, px_per_cm: float, margin_px: int) -> npt.NDArray[np.uint8]:
    """The target drawn flat: its frame's origin at pixel corner (margin, margin), X to
    the right, Y down, ``px_per_cm`` pixels per cm (whole pixels per square or spacing)."""
    import cv2

    s = target.spacing_cm * px_per_cm
    if abs(s - round(s)) > 1e-9:
        raise ArmsigError("board_image needs whole pixels per square",
                          got=f"{s:g} px per {target.spacing_cm:g} cm")  # fmt: skip
    sq, m = int(round(s)), margin_px
    if target.kind in ("charuco", "aruco", "apriltag"):
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, target.dictionary))
        board: Any
        if target.kind == "charuco":
            board = cv2.aruco.CharucoBoard((target.columns, target.rows), target.spacing_cm,
                                           target.marker_cm, d)  # fmt: skip
            size = (target.columns * sq + 2 * m, target.rows * sq + 2 * m)
        else:
            ids = np.arange(target.first_id, target.first_id + target.rows * target.columns)
            gap = target.spacing_cm - target.marker_cm
            board = cv2.aruco.GridBoard((target.columns, target.rows), target.marker_cm, gap, d,
                                        ids.astype(np.int32))  # fmt: skip
            size = (int(round(((target.columns - 1) * target.spacing_cm + target.marker_cm)
                              * px_per_cm)) + 2 * m,
                    int(round(((target.rows - 1) * target.spacing_cm + target.marker_cm)
                              * px_per_cm)) + 2 * m)  # fmt: skip
        img = board.generateImage(size, marginSize=m, borderBits=1)
        out: npt.NDArray[np.uint8] = np.where(img > 127, WHITE, BLACK).astype(np.uint8)
        return out
    if target.kind == "checkerboard":
        img = np.full((target.rows * sq + 2 * m, target.columns * sq + 2 * m), WHITE, np.uint8)
        for r in range(target.rows):
            for c in range(target.columns):
                if (r + c) % 2 == 0:  # the square at the origin's corner is black
                    img[m + r * sq : m + (r + 1) * sq, m + c * sq : m + (c + 1) * sq] = BLACK
        return img
    # circles: centres at (c s, r s) from the origin, a border of one spacing around them
    w = (target.columns - 1) * sq + 2 * (m + sq)
    h = (target.rows - 1) * sq + 2 * (m + sq)
    img = np.full((h, w), WHITE, np.uint8)
    shift = 4  # cv2.circle's fixed-point bits: centres placed to 1/16 px
    for r in range(target.rows):
        for c in range(target.columns):
            radius = sq * (0.35 if target.origin_dot and r == c == 0 else 0.25)
            centre = ((m + sq + c * sq - 0.5) * 16, (m + sq + r * sq - 0.5) * 16)
            cv2.circle(img, (int(round(centre[0])), int(round(centre[1]))),
                       int(round(radius * 16)), BLACK, -1, cv2.LINE_AA, shift)  # fmt: skip
    return img


def board_origin_px(target: Target, px_per_cm: float, margin_px: int) -> float:
    """Where the target frame's origin lies in :func:`board_image` (a pixel-corner
    coordinate, the same on both axes)."""
    extra = target.spacing_cm * px_per_cm if target.kind == "circles" else 0.0
    return margin_px + extra


def render(
    target: Target,
    camera_from_target: npt.ArrayLike,
    lens: Intrinsics,
    *,
    blur_px: float = 0.0,
    noise_grey: float = 0.0,
    rng: np.random.Generator | None = None,
    px_per_cm: float = 40.0,
    margin_px: int = 40,
) -> npt.NDArray[np.uint8]:
    """A grey image (height, width) of ``target`` at pose ``camera_from_target`` (4, 4, cm)
    seen by ``lens`` (its distortion must be zero), blurred by a Gaussian of σ ``blur_px``
    and with noise of σ ``noise_grey`` grey levels (module docstring)."""
    import cv2

    if np.any(lens.dist_coeffs() != 0):
        raise ArmsigError("render draws through an undistorted lens",
                          got=str(lens.dist_coeffs().tolist()))  # fmt: skip
    board = board_image(target, px_per_cm, margin_px)
    T = np.asarray(camera_from_target, float)
    o = board_origin_px(target, px_per_cm, margin_px)
    k = 1.0 / px_per_cm
    # board pixel centre (x, y) -> target frame (cm): X = (x + 0.5 - o) / px_per_cm
    A = np.array([[k, 0.0, (0.5 - o) * k], [0.0, k, (0.5 - o) * k], [0.0, 0.0, 1.0]])
    f = SUPERSAMPLE
    S = np.array([[f, 0.0, (f - 1) / 2], [0.0, f, (f - 1) / 2], [0.0, 0.0, 1.0]])
    H = S @ lens.camera_matrix() @ T[:3][:, [0, 1, 3]] @ A
    size = (lens.width_px * f, lens.height_px * f)
    fine = cv2.warpPerspective(board.astype(np.float32), H, size, flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=128.0)  # fmt: skip
    if blur_px > 0:
        fine = cv2.GaussianBlur(fine, (0, 0), blur_px * f)
    img = cv2.resize(fine, (lens.width_px, lens.height_px), interpolation=cv2.INTER_AREA)
    if noise_grey > 0:
        img = img + (rng or np.random.default_rng(0)).normal(0.0, noise_grey, img.shape)
    grey: npt.NDArray[np.uint8] = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return grey
