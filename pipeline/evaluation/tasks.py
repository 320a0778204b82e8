"""The four grid-touching tasks (Sections 6.5, 6.6 and 7.2.1) and where their fixtures sit.

Each task has a physical fixture (mylar table, cathetometer line set, Ranky
jig on the milling-machine bed, the simulated 12-vertex grid) at a nominal
placement in the robot's base (mounting-surface) frame, three fixture points
that teach the workspace frame (Section 6.5: origin at point 1, X toward
point 2, Z normal to the plane 1-2-3), and its points in fixture coordinates.
Every fixture here is axis-aligned with the base, so the taught frame is the
fixture frame. The tool orientation is constant in the workspace frame:
``R0 = Rot(y, 180°) Rot(z, 90°)`` (Section 7.2.1), tool Z pointing down at the
table, for the 12-vertex grid and the lines. Chapter 6 does not give the
orientation of its pen and test cube; with ``R0`` the Puma's wrist is within a
few degrees of its singularity (θ5 = 0) over the 2-D and 3-D grids, so those
tools are tilted (:data:`TOOL_TILT_DEG`, about the workspace X, then Y), which
keeps |sin θ5| above 0.7 on every vertex, every joint 5° inside its limits and
the elbow 20° from stretched (the planning margins of
:func:`pipeline.evaluation.controllers.plan_branches`).

Placements (Figures 6-15 and 6-16 are lost; the text fixes the rest):

- ``lines1d``: Table 6-7's six lines (coordinates given, the free coordinate's
  range is ours: centred, or starting where the Puma can reach), lengths of
  Table 6-6 (60, 50, 60, 50, 60, 60 cm). Lines 2 and 4 run at 30 cm instead of
  8 cm from the base's Y-Z / X-Z plane: at 8 cm no 50 cm line at z = 38 cm stays
  5° inside the joint limits, 6° off the wrist singularity and 10° off the
  stretched elbow with the probe pointing down. Teach points on the table at
  z = 3 cm (ends of line 1 and a point 30 cm nearer the robot).
- ``grid2d``: 13 x 4 vertices, 5 cm apart, on the table (z = 0), X from -30 to
  30 cm, Y from 40 to 55 cm (Section 6.6.2: 60 x 15 cm, axes along the base's).
  The thesis says "62 vertices"; 13 x 4 = 52.
- ``grid3d``: 7 x 3 x 3 vertices, 60 x 25 x 25 cm, spacing 10 / 12.5 / 12.5 cm
  (Section 6.6.3), X from -30 to 30, Y from 45 to 70, Z from 35 to 60 cm.
- ``grid12``: Table 7-1 (:mod:`pipeline.evaluation.grid12`).

Other robots: the layout is mapped from the Puma's reach with the probe
pointing down onto the robot's (:func:`down_workspace`, :func:`tasks_for`);
whether a mapped task fits is decided when it is taught and solved (tasks
that do not fit are skipped with the reason in the summary and the report).
Arms with fewer than six joints hold the probe only as their joint axes allow
(a SCARA: straight down, yaw free); their down-pointing workspace is their
whole workspace and its edge is hard, so each mapped task is also fitted
inside it (:func:`fit_task`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.evaluation.grid12 import GRID12_TOOL_ROTATION, GRID12_VERTICES_CM
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.transforms import Array, invert_transform, rot_x, rot_y, rot_z, trans
from pipeline.robots.description import RobotDescription
from pipeline.units import joints_to_internal

TASK_NAMES = ("lines1d", "grid2d", "grid3d", "grid12")

#: Table 6-7 lines: (fixed x, y, z with NaN on the free axis), start and end of the
#: free coordinate (cm). Desired lengths are Table 6-6's.
LINES_1D_CM = (
    ((np.nan, 58.0, 3.0), -30.0, 30.0),  # line 1, along X, 60 cm
    ((30.0, np.nan, 38.0), 30.0, 80.0),  # line 2, along Y, 50 cm (x = 8 in Table 6-7)
    ((8.0, 73.0, np.nan), 3.0, 63.0),  # line 3, along Z, 60 cm
    ((np.nan, 30.0, 38.0), 30.0, 80.0),  # line 4, along X, 50 cm (y = 8 in Table 6-7)
    ((-58.0, np.nan, 3.0), -30.0, 30.0),  # line 5, along Y, 60 cm
    ((-73.0, 8.0, np.nan), 3.0, 63.0),  # line 6, along Z, 60 cm
)
LINES_1D_ORIGIN_CM = (30.0, 58.0, 3.0)
GRID2D_ORIGIN_CM = (-30.0, 40.0, 0.0)
GRID2D_SHAPE = (13, 4)
GRID2D_SPACING_CM = 5.0
GRID3D_ORIGIN_CM = (-30.0, 45.0, 35.0)
GRID3D_SHAPE = (7, 3, 3)
GRID3D_SPACING_CM = (10.0, 12.5, 12.5)
#: Instrument resolutions (cm, deg): cathetometer 0.05 mm (Section 6.5.1), machinist's
#: rule 0.25 mm (issue 6; Section 6.5.2 gives no figure), Ranky jig 0.001 in and 0.01°
#: (Section 6.5.3). The 12-vertex grid is the simulated task of Chapter 7: exact poses.
CATHETOMETER_CM = 0.005
RULE_CM = 0.025
RANKY_CM = 0.00254
RANKY_DEG = 0.01


def reading_resolution(task: str, name: str) -> float:
    """Resolution of the reading behind an index (0 when the index is derived from
    several readings at other scales, e.g. perpendicularity, or read exactly)."""
    if task == "lines1d":
        return CATHETOMETER_CM
    if task == "grid2d":
        return RULE_CM
    if task == "grid3d":
        if name.startswith("relative"):
            return RANKY_DEG
        return 0.0 if name.startswith("perpendicularity") else RANKY_CM
    return 0.0


#: Tilt (rx, ry) in degrees of each task's tool about the workspace X, then Y axis, before R0.
TOOL_TILT_DEG = {
    "lines1d": (0.0, 0.0),
    "grid2d": (45.0, 45.0),
    "grid3d": (15.0, 45.0),
    "grid12": (0.0, 0.0),
}
#: Random configurations sampled by :func:`down_workspace`.
REACH_SAMPLES = 4000
#: A probe counts as pointing down within this angle of -Z (deg).
DOWN_CONE_DEG = 30.0
#: :func:`fit_task` keeps tasks this far inside the down workspace's radius (cm): the
#: 90th percentile of a SCARA's radius is 0.5 cm from its hard edge (elbow stretched),
#: and the evaluation rig places fixtures with σ = 0.5 cm; 5 σ keeps every point reachable.
FIT_MARGIN_CM = 2.5


@dataclass(frozen=True, eq=False)
class Task:
    """One grid-touching task.

    Attributes
    ----------
    name : str
        One of :data:`TASK_NAMES`.
    instrument : str
        ``cathetometer``, ``rule``, ``ranky`` or ``exact`` (the simulated Table 7-1 task).
    fixture_in_base : ndarray, shape (4, 4)
        Nominal fixture frame in the robot's base frame (cm).
    teach_cm : ndarray, shape (3, 3)
        The three teach points in fixture coordinates.
    points_cm : ndarray, shape (m, 3)
        Desired tool positions in fixture (= workspace) coordinates.
    tool_rotation : ndarray, shape (3, 3)
        Desired tool orientation in the workspace frame, the same at every point.
    """

    name: str
    instrument: str
    fixture_in_base: Array
    teach_cm: Array
    points_cm: Array
    tool_rotation: Array

    def targets(self) -> Array:
        """Desired tool poses in workspace coordinates, shape (m, 4, 4)."""
        T = np.tile(np.eye(4), (len(self.points_cm), 1, 1))
        T[:, :3, :3] = self.tool_rotation
        T[:, :3, 3] = self.points_cm
        return T


def _lines1d() -> tuple[Array, Array, Array]:
    """Fixture frame in the base, teach points and line end points in fixture coordinates.

    Teach points: the ends of line 1 (from +X to -X) and a point 30 cm nearer
    the robot, so the taught frame is the base's turned 180° about Z.
    """
    pts = []
    for fixed, a, b in LINES_1D_CM:
        for v in (a, b):
            p = np.array(fixed)
            p[np.isnan(p)] = v
            pts.append(p)
    F = trans(*LINES_1D_ORIGIN_CM) @ rot_z(np.pi)
    teach_base = np.array([LINES_1D_ORIGIN_CM, [-30.0, 58.0, 3.0], [30.0, 28.0, 3.0]])
    inv = invert_transform(F)
    to_fixture = lambda p: p @ inv[:3, :3].T + inv[:3, 3]  # noqa: E731
    return F, to_fixture(teach_base), to_fixture(np.array(pts))


def _grid(shape: tuple[int, ...], spacing: tuple[float, ...]) -> Array:
    axes = [np.arange(n) * s for n, s in zip(shape, spacing, strict=True)]
    mesh = np.meshgrid(*axes, indexing="ij")
    pts = np.stack([m.ravel() for m in mesh], axis=-1)
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    return pts


def puma_tasks(tilt: bool = True) -> tuple[Task, ...]:
    """The four tasks at their Puma 560 placements (``tilt=False``: every tool at R0)."""
    F1, teach1, pts1 = _lines1d()
    g2 = _grid(GRID2D_SHAPE, (GRID2D_SPACING_CM,) * 2)
    g3 = _grid(GRID3D_SHAPE, GRID3D_SPACING_CM)
    v12 = GRID12_VERTICES_CM

    def R(name: str) -> Array:
        rx, ry = np.deg2rad(TOOL_TILT_DEG[name]) if tilt else (0.0, 0.0)
        out: Array = (rot_x(rx) @ rot_y(ry))[:3, :3] @ GRID12_TOOL_ROTATION
        return out

    return (
        Task("lines1d", "cathetometer", F1, teach1, pts1, F1[:3, :3].T @ R("lines1d")),
        Task("grid2d", "rule", trans(*GRID2D_ORIGIN_CM), g2[[0, 48, 3]], g2, R("grid2d")),
        Task("grid3d", "ranky", trans(*GRID3D_ORIGIN_CM), g3[[0, 54, 6]], g3, R("grid3d")),
        Task("grid12", "exact", trans(*v12[0]), v12[:3] - v12[0], v12 - v12[0], R("grid12")),
    )


@dataclass(frozen=True)
class DownWorkspace:
    """Where a robot's probe can go pointing down (cm): the 90th percentile of its
    horizontal distance from the base origin, and the 10th-90th percentile band of
    its height."""

    radius_cm: float
    z_low_cm: float
    z_high_cm: float


def down_workspace(robot: RobotDescription, tool: Array) -> DownWorkspace:
    """:class:`DownWorkspace` from random configurations within the joint limits (fixed
    seed) whose tool Z axis is within :data:`DOWN_CONE_DEG` of straight down."""
    d = robot.design_chain()
    chain = SerialChain(d.links, d.prismatic, d.base, tool, d.joint_offsets)  # probe on the flange
    rng = np.random.default_rng(0)  # fixed: the same robot gets the same tasks
    lim = robot.limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (REACH_SAMPLES, robot.n_joints))
    T = forward_kinematics(chain, joints_to_internal(q, robot.prismatic))
    down = T[:, 2, 2] < -np.cos(np.deg2rad(DOWN_CONE_DEG))
    p = T[down, :3, 3] if down.sum() >= 10 else T[:, :3, 3]
    lo, hi = np.percentile(p[:, 2], [10, 90])
    return DownWorkspace(float(np.percentile(np.hypot(p[:, 0], p[:, 1]), 90)), float(lo), float(hi))


def tasks_for(robot: RobotDescription, tool: Array) -> tuple[Task, ...]:
    """The tasks for ``robot`` with nominal tool ``tool`` (last link -> tool, (4, 4)).

    The Puma 560 gets the thesis's numbers. Any other robot gets the same layout
    with every tool at R0 (the tilts only keep the Puma's wrist off its
    singularity), mapped from the Puma's :func:`down_workspace` onto its own:
    horizontally scaled by the ratio of the radii, vertically by the ratio of
    the height bands (at most the horizontal ratio) about the bands' middles.
    """
    if robot.name == "puma560":
        return puma_tasks()
    from pipeline.control.controller import task_axes_for
    from pipeline.kinematics.ik import ALL_AXES
    from pipeline.robots import get_robot

    w, wp = down_workspace(robot, tool), down_workspace(get_robot("puma560"), tool)
    s_xy = w.radius_cm / wp.radius_cm
    s_z = min(s_xy, (w.z_high_cm - w.z_low_cm) / (wp.z_high_cm - wp.z_low_cm))
    mid, mid_p = 0.5 * (w.z_low_cm + w.z_high_cm), 0.5 * (wp.z_low_cm + wp.z_high_cm)
    scale = np.array([s_xy, s_xy, s_z])  # fixture axes are the base's up to a turn about Z
    out = []
    for t in puma_tasks(tilt=False):
        F = t.fixture_in_base.copy()
        F[:2, 3] *= s_xy
        F[2, 3] = mid + s_z * (F[2, 3] - mid_p)
        task = Task(t.name, t.instrument, F, t.teach_cm * scale, t.points_cm * scale,
                    t.tool_rotation)  # fmt: skip
        out.append(task if task_axes_for(robot) == ALL_AXES else fit_task(task, w))
    return tuple(out)


def fit_task(task: Task, w: DownWorkspace) -> Task:
    """``task`` shrunk, where it leaves ``w``, to lie inside it (arms that cannot tilt).

    Horizontally the task is scaled about the base Z axis until its farthest
    point is :data:`FIT_MARGIN_CM` inside ``w.radius_cm``; vertically it is
    scaled about its lowest point until it is no taller than the height band,
    then shifted into the band.
    A task already inside is returned unchanged. The fixture's Z axis is the
    base's (every fixture is level, turned about Z only), so both scalings are
    scalings of fixture coordinates.
    """
    pts = np.concatenate([task.teach_cm, task.points_cm])
    F = task.fixture_in_base.copy()
    p = pts @ F[:3, :3].T + F[:3, 3]
    k = min(1.0, (w.radius_cm - FIT_MARGIN_CM) / float(np.hypot(p[:, 0], p[:, 1]).max()))
    z_min, height = float(p[:, 2].min()), float(np.ptp(p[:, 2]))
    band = w.z_high_cm - w.z_low_cm
    s = min(1.0, band / height) if height > 0.0 else 1.0
    dz = max(w.z_low_cm - z_min, min(0.0, w.z_high_cm - (z_min + s * height)))
    if k == 1.0 and s == 1.0 and dz == 0.0:
        return task
    F[:2, 3] *= k
    F[2, 3] = z_min + s * (F[2, 3] - z_min) + dz
    scale = np.array([k, k, s])
    return Task(task.name, task.instrument, F, task.teach_cm * scale, task.points_cm * scale,
                task.tool_rotation)  # fmt: skip
