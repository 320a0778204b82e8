"""The simulated three-dimensional grid touching task of Section 7.2.1.

Twelve vertices (Table 7-1) in the base frame of the ideal Puma 560, all with
the tool orientation ``Rot(y, 180°) Rot(z, 90°)``, and the 34 performance
indices computed from the poses a controller actually reached.

Reading of the line numbering (the thesis's Figure 7-1 is missing; the text
fixes it up to the order of the Y lines):

* Lines 1, 4, 5, 8 are parallel to X (60 cm) and have the midpoints 9-12 in
  that order, so Line 1 = 1-2, Line 4 = 3-4, Line 5 = 5-6, Line 8 = 7-8.
* Lines 2, 3, 6, 7 are parallel to Y (30 cm): Line 2 = 2-4, Line 3 = 1-3,
  Line 6 = 6-8, Line 7 = 5-7.
* Lines 9-12 are parallel to Z (50 cm): Line 9 = 1-5, Line 10 = 2-6,
  Line 11 = 3-7, Line 12 = 4-8.
* The perpendicularity errors are the X-Y, Y-Z and Z-X angles at the grid
  origin (Vertex 1, the reference of the relative orientation errors). The
  print names "Lines 1 and 3, 3 and 8, 8 and 1", but Line 8 is parallel to X
  by the same section, which would make "Z-X" the angle between two X lines;
  we read the "8" as "9" (the Z line through Vertex 1). This is also what
  fixes Line 3 = 1-3: Lines 1, 3 and 9 are the three edges meeting at Vertex 1.

Vertex numbers in this module are the thesis's (1-based); arrays are 0-based.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pipeline.kinematics.transforms import angle_between, invert_transform, pose_error, rot_y, rot_z

Array = npt.NDArray[np.float64]

#: Table 7-1: desired vertex positions (cm) in the ideal Puma base frame, rows = vertices 1..12.
GRID12_VERTICES_CM: Array = np.array(
    [
        [-30.0, 40.0, 30.0],
        [30.0, 40.0, 30.0],
        [-30.0, 70.0, 30.0],
        [30.0, 70.0, 30.0],
        [-30.0, 40.0, 80.0],
        [30.0, 40.0, 80.0],
        [-30.0, 70.0, 80.0],
        [30.0, 70.0, 80.0],
        [0.0, 40.0, 30.0],
        [0.0, 70.0, 30.0],
        [0.0, 40.0, 80.0],
        [0.0, 70.0, 80.0],
    ]
)
GRID12_VERTICES_CM.setflags(write=False)

#: Section 7.2.1: tool orientation at every vertex, ``Rot(y, 180°) Rot(z, 90°)``.
GRID12_TOOL_ROTATION: Array = (rot_y(np.pi) @ rot_z(np.pi / 2))[:3, :3]
GRID12_TOOL_ROTATION.setflags(write=False)

#: Vertex pairs (1-based) of Lines 1-12, then the diagonals 1-4, 2-3, 5-8, 6-7.
LINE_VERTICES: tuple[tuple[int, int], ...] = (
    (1, 2), (2, 4), (1, 3), (3, 4),  # Lines 1-4 (z = 30 cm)
    (5, 6), (6, 8), (5, 7), (7, 8),  # Lines 5-8 (z = 80 cm)
    (1, 5), (2, 6), (3, 7), (4, 8),  # Lines 9-12 (parallel to Z)
    (1, 4), (2, 3), (5, 8), (6, 7),  # diagonals
)  # fmt: skip
#: (line number, midpoint vertex) of the four normal deviations.
NORMAL_DEVIATIONS: tuple[tuple[int, int], ...] = ((1, 9), (4, 10), (5, 11), (8, 12))
#: Vertices of the radial and absolute orientation errors.
CORNER_VERTICES: tuple[int, ...] = (1, 4, 5, 8)
#: Vertices whose orientation is compared with Vertex 1's.
RELATIVE_VERTICES: tuple[int, ...] = (4, 5, 8)
#: (name, line a, line b) of the perpendicularity errors, lines directed away from Vertex 1.
PERPENDICULAR_LINES: tuple[tuple[str, int, int], ...] = (("xy", 1, 3), ("yz", 3, 9), ("zx", 9, 1))


def _names() -> tuple[list[str], list[bool], list[str]]:
    names: list[str] = []
    signed: list[bool] = []
    units: list[str] = []

    def add(name: str, is_signed: bool, unit: str) -> None:
        names.append(f"{name}_{unit}")
        signed.append(is_signed)
        units.append(unit)

    for k in range(12):
        add(f"line{k + 1}_length_error", True, "cm")
    for a, b in LINE_VERTICES[12:]:
        add(f"diagonal{a}_{b}_length_error", True, "cm")
    for line, _ in NORMAL_DEVIATIONS:
        add(f"line{line}_normal_deviation", False, "cm")
    for v in CORNER_VERTICES:
        add(f"vertex{v}_radial_error", False, "cm")
    for v in CORNER_VERTICES:
        add(f"vertex{v}_orientation_error", False, "deg")
    for v in RELATIVE_VERTICES:
        add(f"vertex{v}_relative_orientation_error", False, "deg")
    for axes, _, _ in PERPENDICULAR_LINES:
        add(f"perpendicularity_{axes}_error", True, "deg")
    return names, signed, units


_N, _S, _U = _names()
#: The 34 index names, in Section 7.2.1's order, unit suffix ``_cm`` / ``_deg``.
INDEX_NAMES: tuple[str, ...] = tuple(_N)
#: True for the 19 signed indices (line lengths and perpendicularity).
INDEX_SIGNED: tuple[bool, ...] = tuple(_S)
#: Unit of each index, ``'cm'`` or ``'deg'``.
INDEX_UNITS: tuple[str, ...] = tuple(_U)


def grid12_targets() -> Array:
    """Desired end-effector poses of the 12 grid vertices (Table 7-1).

    Returns
    -------
    T : ndarray, shape (12, 4, 4)
        Poses in the ideal Puma base frame, positions in cm.
    """
    T = np.zeros((12, 4, 4))
    T[:, :3, :3] = GRID12_TOOL_ROTATION
    T[:, :3, 3] = GRID12_VERTICES_CM
    T[:, 3, 3] = 1.0
    return T


def _line_vectors(p: Array, pairs: tuple[tuple[int, int], ...]) -> Array:
    """End minus start of each vertex pair; ``p`` (..., 12, 3) -> (..., len(pairs), 3)."""
    a = np.array([i - 1 for i, _ in pairs])
    b = np.array([j - 1 for _, j in pairs])
    out: Array = p[..., b, :] - p[..., a, :]
    return out


def indices34(T_actual: npt.ArrayLike, T_desired: npt.ArrayLike) -> Array:
    """The 34 performance indices of Section 7.2.1.

    Parameters
    ----------
    T_actual : array_like, shape (..., 12, 4, 4)
        Poses reached at the 12 vertices (cm), any leading batch axes (robots).
    T_desired : array_like, shape (12, 4, 4)
        Commanded poses, usually :func:`grid12_targets`.

    Returns
    -------
    indices : ndarray, shape (..., 34)
        In the order of :data:`INDEX_NAMES`; lengths in cm, angles in degrees.
    """
    Ta = np.asarray(T_actual, float)
    Td = np.asarray(T_desired, float)
    if Ta.shape[-3:] != (12, 4, 4) or Td.shape != (12, 4, 4):
        raise ValueError(
            f"indices34 expects T_actual (..., 12, 4, 4) and T_desired (12, 4, 4); "
            f"got {Ta.shape} and {Td.shape}. Pass the poses of the 12 grid vertices."
        )
    pa, pd = Ta[..., :3, 3], Td[:, :3, 3]
    va, vd = _line_vectors(pa, LINE_VERTICES), _line_vectors(pd, LINE_VERTICES)
    # 1. Linear displacement: actual minus desired length, 12 lines + 4 diagonals.
    length = np.linalg.norm(va, axis=-1) - np.linalg.norm(vd, axis=-1)
    # 2. Normal deviation: distance of the actual midpoint from the actual line.
    lines = [LINE_VERTICES[n - 1] for n, _ in NORMAL_DEVIATIONS]
    start = pa[..., [a - 1 for a, _ in lines], :]
    direction = _line_vectors(pa, tuple(lines))
    offset = pa[..., [m - 1 for _, m in NORMAL_DEVIATIONS], :] - start
    normal = np.linalg.norm(np.cross(offset, direction), axis=-1) / np.linalg.norm(
        direction, axis=-1
    )
    # 3./4. Radial and absolute orientation errors at the corners.
    corners = [v - 1 for v in CORNER_VERTICES]
    radial, absolute = pose_error(Td[corners], Ta[..., corners, :, :])
    # 5. Relative orientation: actual 1->k rotation against the desired 1->k rotation.
    rel = [v - 1 for v in RELATIVE_VERTICES]
    rel_a = invert_transform(Ta[..., :1, :, :]) @ Ta[..., rel, :, :]
    rel_d = invert_transform(Td[:1]) @ Td[rel]
    _, relative = pose_error(rel_d, rel_a)
    # 6. Perpendicularity: actual angle between the two lines minus the desired angle (90°).
    ia = [a - 1 for _, a, _ in PERPENDICULAR_LINES]
    ib = [b - 1 for _, _, b in PERPENDICULAR_LINES]
    perp = angle_between(va[..., ia, :], va[..., ib, :]) - angle_between(vd[ia], vd[ib])
    return np.concatenate(
        [
            length,
            normal,
            radial,
            np.rad2deg(absolute),
            np.rad2deg(relative),
            np.rad2deg(perp),
        ],
        axis=-1,
    )
