"""Performance indices of the 1-D, 2-D and 3-D grid-touching tasks (Section 6.6).

The 34 indices of the 12-vertex grid (Section 7.2.1) live in
:mod:`pipeline.evaluation.grid12`. Every function takes measured points (and
orientations) with any leading batch shape and the desired ones; lengths in
cm, angles returned in degrees. Signed indices are actual minus desired.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from pipeline.evaluation.geometry import (
    distance,
    normal_deviation,
    rotation_from_vector,
    rotation_vector,
    signed_extreme,
)
from pipeline.kinematics.transforms import Array, angle_between

#: Table 6-6: one signed line-length error per line (cm).
LINES1D_UNIT = "cm"

#: Tables 6-8/6-9 columns: (name, unit, signed).
GRID2D_INDICES: tuple[tuple[str, str, bool], ...] = (
    ("x_line_length_error_cm", "cm", True),
    ("y_line_length_error_cm", "cm", True),
    ("max_normal_deviation_cm", "cm", False),
    ("diagonal1_length_error_cm", "cm", True),
    ("diagonal2_length_error_cm", "cm", True),
)

#: Tables 6-10/6-11 rows: (name, unit, signed).
GRID3D_INDICES: tuple[tuple[str, str, bool], ...] = (
    ("max_normal_deviation_x_cm", "cm", False),
    ("max_normal_deviation_y_cm", "cm", False),
    ("max_normal_deviation_z_cm", "cm", False),
    ("line_length_error_x_cm", "cm", False),
    ("line_length_error_y_cm", "cm", False),
    ("line_length_error_z_cm", "cm", False),
    ("perpendicularity_xy_deg", "deg", True),
    ("perpendicularity_yz_deg", "deg", True),
    ("perpendicularity_zx_deg", "deg", True),
    ("relative_orientation_x_vertex4_deg", "deg", True),
    ("relative_orientation_y_vertex4_deg", "deg", True),
    ("relative_orientation_z_vertex4_deg", "deg", True),
)


def line_length_errors(measured: npt.ArrayLike, desired: npt.ArrayLike) -> Array:
    """Measured minus desired line length (Table 6-6), cm, any matching shapes."""
    out: Array = np.asarray(measured, float) - np.asarray(desired, float)
    return out


def grid2d_indices(marks: npt.ArrayLike, desired: npt.ArrayLike) -> Array:
    """The five columns of Tables 6-8/6-9 from pen marks on the mylar (Section 6.6.2).

    Parameters
    ----------
    marks : array_like, shape (..., nx, ny, 2)
        Mark ``(j, i)`` of vertex column j (along X) and row i (along Y), cm.
    desired : array_like, shape (nx, ny, 2)

    Returns
    -------
    indices : ndarray, shape (..., 5)
        In :data:`GRID2D_INDICES` order: the X-line and Y-line length errors of
        largest magnitude (lines X_i* through marks (1, i), (nx, i); Y_j* through
        (j, 1), (j, ny)), the largest normal deviation of an intermediate mark
        from its X line, and the errors of diagonals (1,1)-(nx,ny) and (nx,1)-(1,ny).
    """
    m = np.asarray(marks, float)
    d = np.asarray(desired, float)

    def lengths(g: Array) -> tuple[Array, Array, Array, Array]:
        x = distance(g[..., 0, :, :], g[..., -1, :, :])  # (..., ny)
        y = distance(g[..., :, 0, :], g[..., :, -1, :])  # (..., nx)
        d1 = distance(g[..., 0, 0, :], g[..., -1, -1, :])
        d2 = distance(g[..., -1, 0, :], g[..., 0, -1, :])
        return x, y, d1, d2

    (xa, ya, d1a, d2a), (xd, yd, d1d, d2d) = lengths(m), lengths(d)
    rows = np.swapaxes(m, -3, -2)  # (..., ny, nx, 2): X line i
    dev = normal_deviation(rows[..., 1:-1, :], rows[..., 0, :], rows[..., -1, :])
    return np.stack(
        [
            signed_extreme(xa - xd),
            signed_extreme(ya - yd),
            dev.max(axis=(-2, -1)),
            d1a - d1d,
            d2a - d2d,
        ],
        axis=-1,
    )


def _families(g: Array) -> list[Array]:
    """Lines of a (..., nx, ny, nz, 3) grid along X, Y, Z: (..., lines, k, 3) each."""
    out = []
    for axis in range(3):
        h = np.moveaxis(g, -4 + axis, -2)  # (..., a, b, k, 3)
        out.append(h.reshape(*h.shape[:-4], -1, h.shape[-2], 3))
    return out


def grid3d_indices(
    p: npt.ArrayLike, w_deg: npt.ArrayLike, p_desired: npt.ArrayLike, w_desired_deg: npt.ArrayLike
) -> Array:
    """The twelve rows of Tables 6-10/6-11 from Ranky-jig readings (Section 6.6.3).

    Parameters
    ----------
    p : array_like, shape (..., nx, ny, nz, 3)
        Measured tool positions, cm.
    w_deg : array_like, shape (..., nx, ny, nz, 3)
        Measured tool orientations as axis-angle vectors (deg) of any fixed
        reference orientation, in the jig's axes (the jig reads deviations).
    p_desired, w_desired_deg : array_like, shape (nx, ny, nz, 3)

    Returns
    -------
    indices : ndarray, shape (..., 12)
        In :data:`GRID3D_INDICES` order. Lines are the border-to-border point
        pairs of each family (9 X, 21 Y, 21 Z lines for 7 x 3 x 3); normal
        deviations are of the intermediate points, maximum over the family;
        length errors the largest magnitude in the family; perpendicularity
        the angle between the families' mean unit directions minus the
        desired angle; the relative orientation at Vertex 4 (corner
        ``(nx, ny, 1)``, numbered as Table 7-1) is the rotation from Vertex 1
        (corner ``(1, 1, 1)``) as an axis-angle vector about the jig's X, Y, Z,
        minus the desired one.
    """
    pa = np.asarray(p, float)
    pd = np.asarray(p_desired, float)
    fa, fd = _families(pa), _families(pd)
    normal = [
        normal_deviation(f[..., 1:-1, :], f[..., 0, :], f[..., -1, :]).max(axis=(-2, -1))
        for f in fa
    ]
    length = [
        np.abs(distance(a[..., 0, :], a[..., -1, :]) - distance(d[..., 0, :], d[..., -1, :])).max(
            axis=-1
        )
        for a, d in zip(fa, fd, strict=True)
    ]

    def mean_dirs(fam: list[Array]) -> list[Array]:
        out = []
        for f in fam:
            u = f[..., -1, :] - f[..., 0, :]
            out.append((u / np.linalg.norm(u, axis=-1, keepdims=True)).mean(axis=-2))
        return out

    ua, ud = mean_dirs(fa), mean_dirs(fd)
    perp = [
        angle_between(ua[i], ua[j]) - angle_between(ud[i], ud[j])
        for i, j in ((0, 1), (1, 2), (2, 0))
    ]

    def relative(w: Array) -> Array:
        R = rotation_from_vector(np.deg2rad(w))
        return rotation_vector(R[..., 0, 0, 0, :, :], R[..., -1, -1, 0, :, :])

    rel = relative(np.asarray(w_deg, float)) - relative(np.asarray(w_desired_deg, float))
    return np.concatenate(
        [np.stack(normal + length, axis=-1), np.degrees(np.stack(perp, axis=-1)), np.degrees(rel)],
        axis=-1,
    )


def improvement(design: npt.ArrayLike, signature: npt.ArrayLike) -> Array:
    """Improvement factor |design error| / |signature error| (Tables 6-10/6-11); inf at 0."""
    d = np.abs(np.asarray(design, float))
    s = np.abs(np.asarray(signature, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        out: Array = np.where(
            s > 0.0, d / np.where(s > 0.0, s, 1.0), np.where(d > 0.0, np.inf, 1.0)
        )
    return out
