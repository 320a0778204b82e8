"""The simulated camera rig (``pipeline simulate NAME --sensor camera``, issue 39).

Two set-ups, each recorded as a pose set (sweep ``poses``: random whole-arm configurations
within the limits, one image each):

- ``eye-to-hand``: a camera fixed in the cell watches a target carried on the flange;
- ``eye-in-hand``: a camera on the flange watches a target fixed in the cell.

The lens (:class:`~pipeline.sensor.camera.Intrinsics`): the rig states its nominal one
(focal length ``focal_px`` on both axes, the principal point at the image centre, no
distortion); the true one has its focal lengths :data:`FOCAL_SIGMA` off (relative), its
principal point :data:`PRINCIPAL_SIGMA_PX` off, and the distortion ``distortion``
(``k1, k2, p1, p2, k3``). Only the truth knows the true lens and the hand-eye transforms.

A detector drops an image (:func:`detect`) when the target's back faces the camera or its
face is more than :data:`MAX_OBLIQUE_DEG` from the line of sight, when it is so far that
neighbouring points are closer than :data:`MIN_SPACING_PX` in the image, and when it is
partly out of view: a checkerboard or circle grid with any point outside the image
(minus :data:`BORDER_PX`), a ChArUco board or marker set with fewer than
:data:`MIN_POINTS` points inside (a marker set keeps only markers wholly inside) or with
its points inside on one line (:func:`_spread`: no pose from one row of corners). Those
configurations are never commanded (the rig draws until ``poses`` images are kept); the
truth counts the drops by reason.

Pixels get Gaussian noise of σ = ``pixel_noise_px`` per coordinate (none when noiseless),
recorded with each image (``sigma_px``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import link_frames
from pipeline.kinematics.transforms import invert_transform, rot_x, rot_z, trans
from pipeline.sensor.camera import Intrinsics, project
from pipeline.sensor.target import Target
from pipeline.units import joints_to_internal

SETUPS = ("eye-to-hand", "eye-in-hand")
#: The default target: a ChArUco board of 6 × 8 squares of 3.5 cm, 35 inner corners.
DEFAULT_TARGET = Target("charuco", 6, 8, 3.5, 2.6, "DICT_5X5_100")
FOCAL_SIGMA = 0.01  # relative: a lens's focal length against its data sheet
PRINCIPAL_SIGMA_PX = 5.0  # the optical axis against the image centre
MAX_OBLIQUE_DEG = 60.0  # corner and marker detectors fail past ~60-70° of obliquity
MIN_SPACING_PX = 10.0  # neighbouring points closer than this are not resolved
BORDER_PX = 2.0  # a point this close to the image edge is not found
MIN_POINTS = 8
#: The found points' smaller principal spread, in spacings, below which they are one row.
MIN_SPREAD = 0.5
#: σ a camera session states when simulated with no pixel noise at all (--pixel-noise 0):
#: the default's, so that its residuals are still weighed in px.
STATED_SIGMA_PX = 0.2  # points a ChArUco or marker detection needs (PnP needs 4, coplanar)
#: Eye-to-hand: the camera 1.5 reaches from the workspace's centre, looking at it from
#: the front, a side and above (world frame); eye-in-hand: the target lies this far out
#: in front of the robot (reaches), facing it.
CAMERA_DISTANCE_REACH = 1.5
CAMERA_DIRECTION = (1.0, 0.35, 0.6)
TARGET_OUT_REACH = 1.1
#: The target's face on the flange (eye-to-hand) and the camera's (eye-in-hand), cm and
#: deg: a few cm off the flange, turned so that no axis is aligned with the flange's.
MOUNT_OFFSET_CM = (2.0, -1.5, 6.0)
MOUNT_TURN_DEG = (4.0, -3.0, 17.0)
#: Configurations drawn per kept image at most (about 1 in 10-40 is kept).
MAX_DRAWS_PER_IMAGE = 2000
DROP_REASONS = ("behind", "back_face", "oblique", "far", "out_of_view")


def nominal_intrinsics(width_px: int, height_px: int, focal_px: float) -> Intrinsics:
    """The lens as the rig states it: ``focal_px`` on both axes, centred, undistorted."""
    return Intrinsics(width_px, height_px, focal_px, focal_px, width_px / 2, height_px / 2)


def true_intrinsics(
    nominal: Intrinsics, distortion: tuple[float, ...], rng: np.random.Generator
) -> Intrinsics:
    """The true lens: the nominal one off by its tolerances, with ``distortion``."""
    f = nominal.fx * (1.0 + FOCAL_SIGMA * rng.normal())
    fy = f * (1.0 + 0.1 * FOCAL_SIGMA * rng.normal())  # pixels are square to ~0.1 %
    c = np.array([nominal.cx, nominal.cy]) + PRINCIPAL_SIGMA_PX * rng.normal(size=2)
    return Intrinsics(nominal.width_px, nominal.height_px, f, fy, c[0], c[1], *distortion)


def mount() -> np.ndarray:
    """The camera's or target's mount on the flange (4, 4): offset, then turned."""
    ax, ay, az = np.radians(MOUNT_TURN_DEG)
    return np.asarray(trans(*MOUNT_OFFSET_CM) @ rot_z(az) @ rot_x(ax) @ _rot_y(ay), float)


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def look_at(eye: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """An optical frame (4, 4) at ``eye`` whose Z looks at ``centre`` and whose Y (image
    down) is the world's −Z made normal to Z (world frame, cm)."""
    z = (centre - eye) / np.linalg.norm(centre - eye)
    y = np.array([0.0, 0.0, -1.0])
    y = y - (y @ z) * z
    y /= np.linalg.norm(y)
    T = np.eye(4)
    T[:3, :3] = np.stack([np.cross(y, z), y, z], axis=1)
    T[:3, 3] = eye
    return T


def target_centre(target: Target) -> np.ndarray:
    """The centre of the target's points in its own frame (3,), cm."""
    return np.asarray(target.points()[1].mean(axis=0), float)


def placement(
    setup: str, chain: Any, limits: np.ndarray, target: Target, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The rig's layout: (the fixed part in the world, the part on the flange), (4, 4) each:
    (camera, target) for eye-to-hand, (target, camera) for eye-in-hand (cm)."""
    n = chain.n_joints
    q = rng.uniform(limits[:, 0], limits[:, 1], (2000, n))
    F = link_frames(chain, joints_to_internal(q, chain.prismatic))
    base = F[0, 0, :3, 3]
    flange = F[:, n, :3, 3]
    centre = flange.mean(axis=0)
    reach = float(np.percentile(np.linalg.norm(flange - base, axis=1), 90))
    on_flange = mount()
    # the target's face looks out of the flange: its Z (into the board) along −Z_flange
    centred = trans(*(-target_centre(target))) if setup == "eye-to-hand" else np.eye(4)
    if setup == "eye-to-hand":
        d = np.array(CAMERA_DIRECTION) / np.linalg.norm(CAMERA_DIRECTION)
        camera = look_at(centre + CAMERA_DISTANCE_REACH * reach * d, centre)
        return camera, np.asarray(on_flange @ rot_x(np.pi) @ centred, float)
    # eye-in-hand: the board stands out in front of the robot, its face towards the base
    out = np.array([1.0, 0.0, 0.0]) * TARGET_OUT_REACH * reach
    at = np.array([base[0], base[1], centre[2]]) + out
    board = look_at(at - np.array([1.0, 0.0, 0.0]), at)  # Z away from the robot
    board[:3, 3] = at
    board = board @ trans(*(-target_centre(target)))
    return np.asarray(board, float), np.asarray(on_flange, float)


def camera_from_target(
    setup: str, fixed: np.ndarray, on_flange: np.ndarray, flange: np.ndarray
) -> np.ndarray:
    """The target's pose in the camera (M, 4, 4) at flange poses ``flange`` (M, 4, 4)."""
    if setup == "eye-to-hand":
        return np.asarray(invert_transform(fixed) @ flange @ on_flange, float)
    return np.asarray(invert_transform(flange @ on_flange) @ fixed, float)


def camera_points(T: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Points ``local`` (N, 3) of the target at its poses ``T`` (M, 4, 4) in the camera,
    shape (M, N, 3) (cm)."""
    return np.asarray(np.einsum("mij,nj->mni", T[:, :3, :3], local) + T[:, None, :3, 3])


def detect(
    target: Target, T: np.ndarray, lens: Intrinsics, local: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a detector finds in the images of the target at poses ``T`` (M, 4, 4) in the
    camera: whether each image is kept (M,), which points are found (M, N), and the drop
    reason of each image (M,), an index into :data:`DROP_REASONS`, −1 for a kept image
    (module docstring)."""
    p_cam = camera_points(T, local)
    M = len(T)
    reason = np.full(M, -1)
    behind: np.ndarray = np.asarray((p_cam[..., 2] <= 0).any(axis=1))
    centre = p_cam.mean(axis=1)
    sight = centre / np.linalg.norm(centre, axis=1, keepdims=True)
    cos_face = np.einsum("mi,mi->m", T[:, :3, 2], sight)  # Z into the board: > 0, face seen
    uv = project(p_cam, lens.vector())
    inside = (
        (uv[..., 0] >= BORDER_PX) & (uv[..., 0] <= lens.width_px - 1 - BORDER_PX)
        & (uv[..., 1] >= BORDER_PX) & (uv[..., 1] <= lens.height_px - 1 - BORDER_PX)
        & ~behind[:, None]
    )  # fmt: skip
    if target.kind in ("aruco", "apriltag"):  # a marker is found whole or not at all
        inside = np.repeat(inside.reshape(M, -1, 4).all(axis=2), 4, axis=1)
    spacing = target.marker_cm if target.kind in ("aruco", "apriltag") else target.spacing_cm
    spacing_px = lens.fx * spacing / np.maximum(np.linalg.norm(centre, axis=1), 1e-9)
    enough = inside.all(axis=1) if target.whole_board else inside.sum(axis=1) >= MIN_POINTS
    enough &= _spread(inside, local, spacing)
    for k, bad in enumerate(
        [behind, cos_face <= 0, cos_face < np.cos(np.radians(MAX_OBLIQUE_DEG)),
         spacing_px < MIN_SPACING_PX, ~enough]
    ):  # fmt: skip
        reason[(reason < 0) & bad] = k
    return reason < 0, inside, reason


def _spread(found: np.ndarray, local: np.ndarray, spacing: float) -> np.ndarray:
    """Whether each image's found points (M, N) span the target in two directions: a
    detector gives no pose from one row of corners (OpenCV's ChArUco pose needs points
    off one line), and neither does a PnP. The smaller principal spread of the found
    points must reach :data:`MIN_SPREAD` of a spacing."""
    w = found.astype(float)
    n = np.maximum(w.sum(axis=1), 1.0)
    mean = (w @ local[:, :2]) / n[:, None]
    d = local[None, :, :2] - mean[:, None, :]  # (M, N, 2)
    C = np.einsum("mn,mni,mnj->mij", w, d, d) / n[:, None, None]
    smaller = np.linalg.eigvalsh(C)[:, 0]
    return np.asarray(smaller >= (MIN_SPREAD * spacing) ** 2)


def planned_images(
    q: np.ndarray, setup: str, chain: Any, target: Target, fixed: np.ndarray,
    on_flange: np.ndarray, lens: Intrinsics,
) -> tuple[np.ndarray, dict[str, Any]]:  # fmt: skip
    """The configurations of a pose plan ``q`` (K, n, boundary units) whose image a
    detector keeps, in the plan's order, and the count of dropped ones by reason with the
    plan's step of every kept one (``plan_steps``)."""
    _, local = target.points()
    flange = link_frames(chain, joints_to_internal(q, chain.prismatic))[:, chain.n_joints]
    ok, _, reason = detect(target, camera_from_target(setup, fixed, on_flange, flange), lens,
                           local)  # fmt: skip
    if ok.sum() < 4:
        raise ArmsigError(
            f"the simulated camera sees the target in {int(ok.sum())} of the plan's {len(q)} poses",
            expected="4 or more images",
            got=", ".join(f"{k}: {int((reason == i).sum())}" for i, k in enumerate(DROP_REASONS)),
            fix="plan for this camera and set-up (`pipeline plan --sensor camera --setup ...` "
            "with the same camera options)",
        )
    dropped: dict[str, Any] = {k: int((reason == i).sum()) for i, k in enumerate(DROP_REASONS)}
    return q[ok], {**dropped, "plan_steps": np.flatnonzero(ok).tolist()}


def draw_images(
    n_images: int, setup: str, chain: Any, limits: np.ndarray, target: Target,
    fixed: np.ndarray, on_flange: np.ndarray, lens: Intrinsics, rng: np.random.Generator,
) -> tuple[np.ndarray, dict[str, int]]:  # fmt: skip
    """``n_images`` configurations (n_images, n) in boundary units whose image a detector
    keeps, and the count of dropped draws by reason."""
    _, local = target.points()
    n = chain.n_joints
    kept: list[np.ndarray] = []
    dropped = dict.fromkeys(DROP_REASONS, 0)
    for _ in range(MAX_DRAWS_PER_IMAGE * n_images // 256 + 1):
        q = rng.uniform(limits[:, 0], limits[:, 1], (256, n))
        flange = link_frames(chain, joints_to_internal(q, chain.prismatic))[:, n]
        T = camera_from_target(setup, fixed, on_flange, flange)
        ok, _, reason = detect(target, T, lens, local)
        for k, name in enumerate(DROP_REASONS):
            dropped[name] += int((reason == k).sum())
        kept.extend(q[ok])
        if len(kept) >= n_images:
            return np.array(kept[:n_images]), dropped
    raise ArmsigError(
        f"the simulated camera sees the target in {len(kept)} of "
        f"{MAX_DRAWS_PER_IMAGE * n_images} random configurations",
        expected=f"{n_images} images",
        got=", ".join(f"{k}: {v}" for k, v in dropped.items()),
        fix="a larger target (--target FILE) or a shorter focal length (--focal-px)",
    )
