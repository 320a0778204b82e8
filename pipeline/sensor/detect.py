"""Find a target's points in an image with OpenCV's detectors (issue 40).

:func:`detect_target` takes one grey image (H, W) uint8 and a
:class:`~pipeline.sensor.target.Target` and returns an :class:`ImageDetection`: each found
point's id (the target's point ids) and its pixel ``(u, v)`` (OpenCV's convention, the
centre of the top-left pixel at (0, 0)), the detector's own quality numbers, and why the
image was dropped when it was. The detectors, by target kind:

- ``charuco``: ``cv2.aruco.CharucoDetector`` (markers refined against the board); its
  corner ids are the target's;
- ``checkerboard``: ``cv2.findChessboardCornersSB`` (default flags), else
  ``cv2.findChessboardCorners``, refined by ``cv2.cornerSubPix``; the grid is numbered from
  the corner whose outer square is black, so that Z = X × Y points into the board (the
  target's frame); a board that looks the same turned 180° (rows + columns even) has no
  such corner and its images are dropped (``ambiguous``);
- ``circles``: ``cv2.findCirclesGrid`` (symmetric grid, dark circles found by a
  ``SimpleBlobDetector``). In OpenCV's order (a symmetric grid looks the same turned
  180°, so that order may flip between images: measured, a 5 × 4 grid turned 160° came
  back numbered from the other end), or, with ``origin_dot``, numbered from the
  larger dot that marks the origin (industrial_calibration's "modified circle grid"):
  id 0 at the large dot, Z = X × Y into the board;
- ``aruco`` / ``apriltag``: ``cv2.aruco.ArucoDetector`` (sub-pixel corner refinement);
  marker ``m``'s corners are points ``4 m + k``; markers of other ids are left out.

Quality numbers: ``markers`` decoded (ChArUco, marker grids), ``edge_width_px`` (OpenCV's
``estimateChessboardSharpness``: the 10-90 % width of the black-white transition, for a
checkerboard or a ChArUco board seen whole), and per point ``size_px`` (a circle's blob
diameter; NaN for corners). Drop reasons (:data:`DROP_REASONS`): ``not_found`` (no board,
or no marker of it), ``too_few_points`` (fewer than ``min_points``), ``blur`` (an edge
wider than ``max_edge_width_px``), ``ambiguous`` (no way to number the points).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError
from pipeline.quiet import debugging
from pipeline.sensor.target import Target

Array = npt.NDArray[np.float64]
DROP_REASONS = ("not_found", "too_few_points", "blur", "ambiguous")
#: cornerSubPix's search window half-size (px) and stop rule for a checkerboard found by the
#: classic detector: OpenCV's calibration tutorial values.
SUBPIX_HALF_WINDOW = 5
SUBPIX_CRITERIA = (3, 100, 1e-4)  # COUNT + EPS, 100 iterations, 1e-4 px
#: The larger origin dot of a modified circle grid is at least this much larger (diameter,
#: relative to its grid neighbours) than the other corners' dots, else no corner is marked.
#: Measured on industrial_calibration's 15 real images: the origin dot 1.87-2.06 × its
#: neighbours, the next corner 0.98-1.09 ×, a ratio of 1.81-2.07; a rendered dot 1.4 × its
#: neighbours' diameter passes. 1.15 stays above the other corners' spread (±10 %).
ORIGIN_DOT_MARGIN = 1.15


@dataclass(frozen=True)
class DetectorSettings:
    """What a detection keeps: at least ``min_points`` points (a pose from coplanar points
    needs 4; 6 leave 4 residual coordinates to check it by), and edges at most
    ``max_edge_width_px`` wide. OpenCV's documentation calls below ~3 px sharp; measured:
    industrial_calibration's real ChArUco images 3.1-5.2 px (all calibrate), a rendered
    ChArUco board blurred by σ = 1 and 2 px 3.2 and 5.5 px with its corners still within
    0.05 px, and at σ = 3 px no marker decodes (tests/test_camera_detect.py). So 6 px:
    the widest edges that were seen to detect well."""

    min_points: int = 6
    max_edge_width_px: float = 6.0

    def __post_init__(self) -> None:
        if self.min_points < 4 or not self.max_edge_width_px > 0:
            raise ArmsigError(
                "detector settings out of range",
                expected="min_points >= 4 and max_edge_width_px > 0",
                got=f"min_points={self.min_points}, max_edge_width_px={self.max_edge_width_px}",
            )


@dataclass(frozen=True)
class ImageDetection:
    """One image's detection: ``point_ids`` (N,), ``uv_px`` (N, 2), ``size_px`` (N,),
    ``markers`` (-1: the target has none), ``edge_width_px`` (NaN: not measured),
    ``dropped`` ("" when kept, else one of :data:`DROP_REASONS`) and ``why`` (one line)."""

    point_ids: npt.NDArray[np.int64]
    uv_px: Array
    size_px: Array
    markers: int = -1
    edge_width_px: float = float("nan")
    dropped: str = ""
    why: str = ""

    @property
    def kept(self) -> bool:
        return not self.dropped


def no_points(
    reason: str, why: str, markers: int = -1, width: float = float("nan")
) -> ImageDetection:
    """A dropped image's detection: no points, the reason and why in words."""
    empty = np.zeros(0)
    return ImageDetection(np.zeros(0, np.int64), np.zeros((0, 2)), empty, markers, width,
                          reason, why)  # fmt: skip


def image_message(
    step: int, file: str, sha256: str, found: ImageDetection, size_px: tuple[int, int] | None
) -> dict[str, Any]:
    """The ``/camera/images`` message of one image (``schemas/mcap/camera_images.json``):
    its file, hash and what its detection found, in sweep ``poses``."""
    out: dict[str, Any] = {
        "sweep": "poses", "step": step, "file": file, "sha256": sha256,
        "dropped": found.dropped, "why": found.why, "markers": found.markers,
        "edge_width_px": None if np.isnan(found.edge_width_px) else round(found.edge_width_px, 3),
    }  # fmt: skip
    if size_px is not None:
        out["width_px"], out["height_px"] = size_px
    return out


def detect_file(
    path: Path, target: Target, settings: DetectorSettings | None = None
) -> tuple[ImageDetection, tuple[int, int] | None]:
    """The target's points in the image file ``path`` and the image's (width, height); a
    missing or undecodable file is a drop (``missing``, ``unreadable``; size None)."""
    import cv2

    if not path.is_file():
        return no_points("missing", "no such file"), None
    with _libpng_quiet():
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)  # 8-bit grey, also from 16-bit
    if image is None:
        return no_points("unreadable", "OpenCV cannot decode it (not an image, or "
                         "corrupted)"), None  # fmt: skip
    grey = np.asarray(image, np.uint8)
    return detect_target(grey, target, settings), (grey.shape[1], grey.shape[0])


@contextlib.contextmanager
def _libpng_quiet() -> Iterator[None]:
    """libpng writes "libpng error: Read Error" straight to the process's stderr (fd 2)
    for a corrupted PNG, past Python and OpenCV's log level; armsig says it in one line
    itself, so fd 2 points at /dev/null while OpenCV decodes (unless ARMSIG_DEBUG=1)."""
    if debugging():
        yield
        return
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def detect_target(
    image: npt.NDArray[np.uint8], target: Target, settings: DetectorSettings | None = None
) -> ImageDetection:
    """The target's points in a grey ``image`` (H, W) uint8 (module docstring)."""
    settings = settings or DetectorSettings()
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ArmsigError("detect_target takes a grey image", expected="(H, W) uint8",
                          got=f"{image.shape} {image.dtype}")  # fmt: skip
    kind = target.kind
    if kind == "charuco":
        found = _charuco(image, target)
    elif kind == "checkerboard":
        found = _checkerboard(image, target)
    elif kind == "circles":
        found = _circles(image, target)
    else:
        found = _markers(image, target)
    if found.dropped:
        return found
    n = len(found.point_ids)
    if n < settings.min_points:
        return no_points("too_few_points", f"{n} points found, fewer than {settings.min_points}",
                     found.markers, found.edge_width_px)  # fmt: skip
    if found.edge_width_px > settings.max_edge_width_px:
        return no_points("blur", f"edges {found.edge_width_px:.1f} px wide, over "
                     f"{settings.max_edge_width_px:g} px", found.markers,
                     found.edge_width_px)  # fmt: skip
    order = np.argsort(found.point_ids, kind="stable")
    return ImageDetection(found.point_ids[order], found.uv_px[order], found.size_px[order],
                          found.markers, found.edge_width_px)  # fmt: skip


def _dictionary(name: str) -> Any:
    import cv2

    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def _edge_width(image: npt.NDArray[np.uint8], inner: tuple[int, int], uv: Array) -> float:
    """OpenCV's average edge width (px) of a whole chessboard whose inner corners ``uv``
    (N, 2) are in row order of a ``inner`` = (columns, rows) pattern."""
    import cv2

    value: Any = cv2.estimateChessboardSharpness(
        image, inner, uv.astype(np.float32).reshape(-1, 1, 2)
    )
    return float(value[0][0])  # (Scalar(mean width, min, max brightness, 0), per-edge array)


def _charuco(image: npt.NDArray[np.uint8], t: Target) -> ImageDetection:
    import cv2

    board = cv2.aruco.CharucoBoard((t.columns, t.rows), t.spacing_cm, t.marker_cm,
                                   _dictionary(t.dictionary))  # fmt: skip
    params = cv2.aruco.CharucoParameters()
    params.tryRefineMarkers = (
        True  # recovers markers the first pass missed (real set: 294 -> 382 corners)
    )
    detector = cv2.aruco.CharucoDetector(board, params)
    corners, ids, _, marker_ids = detector.detectBoard(image)
    markers = 0 if marker_ids is None else len(marker_ids)
    if ids is None or not len(ids):
        return no_points("not_found", f"{markers} markers of the board found, no corner", markers)
    pid = np.asarray(ids, np.int64).reshape(-1)
    uv = np.asarray(corners, float).reshape(-1, 2)
    width = float("nan")
    inner = (t.columns - 1, t.rows - 1)
    if len(pid) == inner[0] * inner[1]:
        width = _edge_width(image, inner, uv[np.argsort(pid)])
    return ImageDetection(pid, uv, np.full(len(pid), np.nan), markers, width)


def _grid_orders(rows: int, cols: int, shape: tuple[int, int]) -> list[npt.NDArray[np.int64]]:
    """Index arrays into a detected ``rows × cols`` grid (flattened) under the grid's
    symmetries (turns and the transpose) that give it ``shape``."""
    base = np.arange(rows * cols).reshape(rows, cols)
    out = []
    for g in (base, base.T):
        for k in range(4):
            r = np.rot90(g, k)
            if r.shape == shape:
                out.append(r.copy())
    return out


def _handed(uv: Array) -> bool:
    """Z = X × Y points into the board: in the image (v down) the row direction turns to
    the column direction clockwise, so their 2-D cross product is positive."""
    x = uv[0, -1] - uv[0, 0]
    y = uv[-1, 0] - uv[0, 0]
    return bool(x[0] * y[1] - x[1] * y[0] > 0)


def _checkerboard(image: npt.NDArray[np.uint8], t: Target) -> ImageDetection:
    import cv2

    inner = (t.columns - 1, t.rows - 1)
    # default flags + cornerSubPix: 0.4-0.6 s a 1600 × 1200 image, rendered corners within
    # 0.058-0.069 px; EXHAUSTIVE | ACCURACY: 2-3.4 s for 0.033-0.057 px
    ok, corners = cv2.findChessboardCornersSB(image, inner, flags=0)
    if not ok:
        ok, corners = cv2.findChessboardCorners(image, inner)
        if not ok:
            return no_points("not_found", f"no {inner[0]} × {inner[1]} inner-corner chessboard")
    corners = cv2.cornerSubPix(image, corners.astype(np.float32), (SUBPIX_HALF_WINDOW,) * 2,
                               (-1, -1), SUBPIX_CRITERIA)  # fmt: skip
    grid = np.asarray(corners, float).reshape(inner[1], inner[0], 2)
    width = _edge_width(image, inner, grid.reshape(-1, 2))
    chosen = []
    for idx in _grid_orders(inner[1], inner[0], (inner[1], inner[0])):
        g = grid.reshape(-1, 2)[idx]
        if _handed(g) and _outer_square_dark(image, g):
            chosen.append(g)
    if len(chosen) != 1:
        why = (
            f"{len(chosen)} ways to number the corners (rows + columns even: the same turned 180°)"
        )
        return no_points("ambiguous", why, -1, width)
    uv = chosen[0].reshape(-1, 2)
    return ImageDetection(np.arange(len(uv), dtype=np.int64), uv, np.full(len(uv), np.nan), -1,
                          width)  # fmt: skip


def _outer_square_dark(image: npt.NDArray[np.uint8], g: Array) -> bool:
    """The square diagonally outside corner (0, 0) is darker than its neighbour along X."""
    ex, ey = g[0, 1] - g[0, 0], g[1, 0] - g[0, 0]  # one square along X and along Y
    h, w = image.shape
    vals = []
    for p in (g[0, 0] - 0.5 * ex - 0.5 * ey, g[0, 0] + 0.5 * ex - 0.5 * ey):
        u, v = int(round(p[0])), int(round(p[1]))
        if not (0 <= u < w and 0 <= v < h):
            return False
        vals.append(float(image[v, u]))
    return vals[0] < vals[1]


def _blob_detector() -> Any:
    """OpenCV's blob detector for dark, filled, convex dots (industrial_calibration's
    circle-detector settings: thresholds 20-220, area 25-5000 px², convexity >= 0.95)."""
    import cv2

    cv: Any = cv2  # the stubs lack the blob detector's factory
    p = cv.SimpleBlobDetector_Params()
    p.minThreshold, p.maxThreshold, p.thresholdStep = 20, 220, 10
    p.filterByColor, p.blobColor = True, 0
    p.filterByArea, p.minArea, p.maxArea = True, 25.0, 5000.0
    p.filterByCircularity = p.filterByInertia = False
    p.filterByConvexity, p.minConvexity = True, 0.95
    return cv.SimpleBlobDetector_create(p)


def _circles(image: npt.NDArray[np.uint8], t: Target) -> ImageDetection:
    import cv2

    blobs = _blob_detector()
    flags = cv2.CALIB_CB_SYMMETRIC_GRID
    find: Any = cv2.findCirclesGrid
    ok, centres = find(image, (t.columns, t.rows), flags=flags, blobDetector=blobs)
    shape = (t.rows, t.columns)
    if not ok and t.rows != t.columns:  # the board turned 90°: OpenCV's rows are its columns
        ok, centres = find(image, shape, flags=flags, blobDetector=blobs)
        shape = (t.columns, t.rows)
    if not ok:
        return no_points("not_found", f"no {t.columns} × {t.rows} circle grid")
    uv = np.asarray(centres, float).reshape(-1, 2)
    keys = blobs.detect(image)  # type: ignore[attr-defined]
    pts = np.array([k.pt for k in keys], float).reshape(-1, 2)
    sizes = np.array([k.size for k in keys], float)
    nearest = np.argmin(((uv[:, None, :] - pts[None]) ** 2).sum(-1), axis=1)
    size = sizes[nearest]
    if not t.origin_dot:
        if shape != (t.rows, t.columns):
            return no_points("ambiguous", "the grid is turned 90° and has no origin mark")
        return ImageDetection(np.arange(len(uv), dtype=np.int64), uv, size)
    return _origin_dot_order(uv.reshape(*shape, 2), size.reshape(shape), t)


def _origin_dot_order(grid: Array, size: Array, t: Target) -> ImageDetection:
    """Number a modified circle grid from its larger origin dot (module docstring)."""
    r, c = grid.shape[:2]

    def relative(i: int, j: int) -> float:  # a corner dot's size against its two neighbours
        ni, nj = (1 if i == 0 else r - 2), (1 if j == 0 else c - 2)
        return float(size[i, j] / (0.5 * (size[ni, j] + size[i, nj])))

    corners = {(i, j): relative(i, j) for i in (0, r - 1) for j in (0, c - 1)}
    best = max(corners, key=corners.__getitem__)
    rest = max(v for k, v in corners.items() if k != best)
    if corners[best] < ORIGIN_DOT_MARGIN * rest:
        why = f"no corner dot stands out ({corners[best]:.2f}, next {rest:.2f} × its neighbours)"
        return no_points("ambiguous", why)
    flat_uv, flat_size = grid.reshape(-1, 2), size.reshape(-1)
    origin = best[0] * c + best[1]
    for idx in _grid_orders(r, c, (t.rows, t.columns)):
        if idx[0, 0] == origin and _handed(flat_uv[idx]):
            return _ordered(flat_uv, flat_size, idx)
    return no_points("ambiguous", "the origin dot is at a corner the target file does not "
                 "describe (the board seen mirrored?)")  # fmt: skip


def _ordered(uv: Array, size: Array, idx: npt.NDArray[np.int64]) -> ImageDetection:
    flat = idx.reshape(-1)
    return ImageDetection(np.arange(len(flat), dtype=np.int64), uv[flat], size[flat])


def _markers(image: npt.NDArray[np.uint8], t: Target) -> ImageDetection:
    import cv2

    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(_dictionary(t.dictionary), params)
    corners, ids, _ = detector.detectMarkers(image)
    if ids is None or not len(ids):
        return no_points("not_found", f"no {t.dictionary} marker", 0)
    ids = np.asarray(ids, np.int64).reshape(-1)
    on_board = (ids >= t.first_id) & (ids < t.first_id + t.rows * t.columns)
    if not on_board.any():
        return no_points("not_found", f"{len(ids)} markers, none of the board's ids "
                     f"{t.first_id}..{t.first_id + t.rows * t.columns - 1}", 0)  # fmt: skip
    uv = np.asarray(corners, float).reshape(-1, 4, 2)[on_board].reshape(-1, 2)
    pid = (4 * ids[on_board][:, None] + np.arange(4)[None]).reshape(-1)
    return ImageDetection(pid, uv, np.full(len(pid), np.nan), int(on_board.sum()))
