"""Render a camera image of a target (issue 40): the board drawn at a known pose through a
pinhole camera, with blur and noise, so that detectors are tested against the truth.

The board is drawn flat (:func:`board_image`: ``px_per_cm`` pixels per cm, ``margin_px``
of white around it) and warped by the homography of the pose into an image
``SUPERSAMPLE`` times finer than the camera's, blurred there (σ in camera pixels), then
averaged down to the camera's pixels (``cv2.INTER_AREA``: each pixel integrates its area,
as a sensor's pixel does) and given Gaussian grey-level noise. Pixel centres follow
OpenCV's convention: the top-left pixel's centre is (0, 0), in the board image as in the
camera's.

A distorted lens (issue 40's simulated sessions, ``simulate --images``): each fine sample
is taken where the undistorted pinhole sees what the lens puts at that sample. Where that
is (:func:`undistorted_shift`) is solved exactly at every camera pixel's centre
(OpenCV's ``undistortPointsIter``, checked by ``projectPoints`` to 1e-6 px) and
interpolated linearly to the fine samples between them: 2e-5 px or less off the exact
shift there (measured, 1280 × 960, the simulator's default lens), except within half a
pixel of the image's edge, where it is held at the edge pixel's (0.06 px off). Lighting: a
vignette, the grey levels times ``1 − vignette · r²`` (``r`` the distance from the
image's centre over its half-diagonal), before the noise.
"""

from __future__ import annotations

from functools import lru_cache
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


def undistorted_shift(lens: Intrinsics) -> npt.NDArray[np.float32]:
    """(height, width, 2) px: where the lens's undistorted pinhole (the same ``fx, fy, cx,
    cy``, no distortion) sees what ``lens`` puts at each pixel's centre, minus that centre."""
    return _shift(lens.width_px, lens.height_px, tuple(float(v) for v in lens.vector()))


#: OpenCV's undistortion iterations (a lens within ``simulate``'s defaults converges to
#: 1e-12 px in 20), and what the shift must reproduce (px) for an image to be rendered
UNDISTORT_ITERATIONS, SHIFT_TOL_PX = 30, 1e-6


@lru_cache(maxsize=2)
def _shift(w: int, h: int, vector: tuple[float, ...]) -> npt.NDArray[np.float32]:
    import cv2

    v = np.asarray(vector)
    K = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])
    grid = np.stack(np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float)), -1)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, UNDISTORT_ITERATIONS, 1e-14)
    und = cv2.undistortPointsIter(grid.reshape(-1, 1, 2), K, v[4:], np.eye(3), K, crit)
    und = np.asarray(und, float).reshape(-1, 2)  # px of the undistorted pinhole
    p = np.concatenate([(und - v[2:4]) / v[:2], np.ones((len(und), 1))], axis=1)
    back, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), K, v[4:])
    miss = float(np.max(np.abs(back.reshape(-1, 2) - grid.reshape(-1, 2))))
    if not miss <= SHIFT_TOL_PX:
        raise ArmsigError("the lens is too strongly distorted to render",
                          expected=f"undistortion to {SHIFT_TOL_PX:g} px at every pixel",
                          got=f"{miss:.3g} px off",
                          fix="--distortion of smaller terms")  # fmt: skip
    out: npt.NDArray[np.float32] = (und - grid.reshape(-1, 2)).reshape(h, w, 2).astype(np.float32)
    return out


def render(
    target: Target,
    camera_from_target: npt.ArrayLike,
    lens: Intrinsics,
    *,
    blur_px: float = 0.0,
    noise_grey: float = 0.0,
    vignette: float = 0.0,
    rng: np.random.Generator | None = None,
    px_per_cm: float = 40.0,
    margin_px: int = 40,
) -> npt.NDArray[np.uint8]:
    """A grey image (height, width) of ``target`` at pose ``camera_from_target`` (4, 4, cm)
    seen by ``lens`` (with its distortion), blurred by a Gaussian of σ ``blur_px``, dimmed
    towards the corners by ``vignette`` and with noise of σ ``noise_grey`` grey levels
    (module docstring)."""
    import cv2

    board = board_image(target, px_per_cm, margin_px).astype(np.float32)
    T = np.asarray(camera_from_target, float)
    o = board_origin_px(target, px_per_cm, margin_px)
    k = 1.0 / px_per_cm
    # board pixel centre (x, y) -> target frame (cm): X = (x + 0.5 - o) / px_per_cm
    A = np.array([[k, 0.0, (0.5 - o) * k], [0.0, k, (0.5 - o) * k], [0.0, 0.0, 1.0]])
    f = SUPERSAMPLE
    w, h = lens.width_px, lens.height_px
    H = lens.camera_matrix() @ T[:3][:, [0, 1, 3]] @ A  # board px -> undistorted camera px
    if np.any(lens.dist_coeffs() != 0):
        fine = _warp_distorted(board, H, lens)
    else:
        S = np.array([[f, 0.0, (f - 1) / 2], [0.0, f, (f - 1) / 2], [0.0, 0.0, 1.0]])
        fine = np.asarray(cv2.warpPerspective(
            board, S @ H, (w * f, h * f), flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT, borderValue=128.0), np.float32)  # fmt: skip
    if blur_px > 0:
        fine = np.asarray(cv2.GaussianBlur(fine, (0, 0), blur_px * f), np.float32)
    img = cv2.resize(fine, (w, h), interpolation=cv2.INTER_AREA)
    if vignette > 0:
        u, v = np.meshgrid(np.arange(w) - (w - 1) / 2, np.arange(h) - (h - 1) / 2)
        img = img * (1.0 - vignette * (u * u + v * v) / (((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2))
    if noise_grey > 0:
        img = img + (rng or np.random.default_rng(0)).normal(0.0, noise_grey, img.shape)
    grey: npt.NDArray[np.uint8] = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return grey


#: Fine rows remapped at once (bounds the memory of a large image's maps)
STRIP_ROWS = 512


def _warp_distorted(
    board: npt.NDArray[np.float32], H: np.ndarray, lens: Intrinsics
) -> npt.NDArray[np.float32]:
    """The fine image of ``board`` through the distorted ``lens`` (module docstring)."""
    import cv2

    f, w, h = SUPERSAMPLE, lens.width_px, lens.height_px
    # the shift at each fine sample's centre ((i − (f − 1)/2) / f in camera px): cv2.resize
    # INTER_LINEAR samples the pixel-centre grid exactly there
    shift = cv2.resize(undistorted_shift(lens), (w * f, h * f), interpolation=cv2.INTER_LINEAR)
    Hi = np.linalg.inv(H)
    u = (np.arange(w * f) - (f - 1) / 2) / f
    out = np.empty((h * f, w * f), np.float32)
    for r0 in range(0, h * f, STRIP_ROWS):
        rows = np.arange(r0, min(r0 + STRIP_ROWS, h * f))
        v = (rows - (f - 1) / 2) / f
        uu = u[None, :] + shift[rows, :, 0]
        vv = v[:, None] + shift[rows, :, 1]
        z = Hi[2, 0] * uu + Hi[2, 1] * vv + Hi[2, 2]
        mx = ((Hi[0, 0] * uu + Hi[0, 1] * vv + Hi[0, 2]) / z).astype(np.float32)
        my = ((Hi[1, 0] * uu + Hi[1, 1] * vv + Hi[1, 2]) / z).astype(np.float32)
        out[rows] = cv2.remap(board, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=128.0)  # fmt: skip
    return out
