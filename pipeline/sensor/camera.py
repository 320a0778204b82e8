"""The camera model: a pinhole with OpenCV's radial-tangential ("plumb bob") distortion.

A point ``P = (X, Y, Z)`` in the camera's optical frame (Z along the optical axis, X to
the image's right, Y down: OpenCV and ROS REP 103's ``*_optical_frame``) projects to the
pixel ``(u, v)`` as OpenCV's ``projectPoints`` does:

    ``x' = X / Z``, ``y' = Y / Z``, ``r² = x'² + y'²``
    ``ρ = 1 + k1 r² + k2 r⁴ + k3 r⁶``
    ``x'' = x' ρ + 2 p1 x' y' + p2 (r² + 2 x'²)``
    ``y'' = y' ρ + p1 (r² + 2 y'²) + 2 p2 x' y'``
    ``u = fx x'' + cx``, ``v = fy y'' + cy``

The intrinsics are named and ordered as OpenCV names them (:data:`INTRINSIC_NAMES`: the
camera matrix's ``fx, fy, cx, cy``, then ``distCoeffs``' ``k1, k2, p1, p2, k3``), so a
``cv2.calibrateCamera`` result goes in and comes out unchanged (:meth:`Intrinsics.from_opencv`,
:meth:`Intrinsics.opencv`). Focal lengths and the principal point are in px, the
distortion coefficients unitless; the point's unit cancels (cm at armsig's boundaries).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError

Array = npt.NDArray[np.float64]

#: The intrinsics in OpenCV's order: camera matrix, then ``distCoeffs`` (5 terms).
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
INTRINSIC_UNITS = ("px", "px", "px", "px", "", "", "", "", "")
#: Points this close to the camera's plane (|Z|, in the point's unit) have no projection.
MIN_DEPTH = 1e-9


@dataclass(frozen=True)
class Intrinsics:
    """A camera's image size (px) and its intrinsics (module docstring)."""

    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    def __post_init__(self) -> None:
        values = self.vector()
        if not np.isfinite(values).all():
            raise ArmsigError("camera intrinsics must be finite numbers", got=str(values.tolist()))
        if self.fx <= 0 or self.fy <= 0 or self.width_px < 1 or self.height_px < 1:
            raise ArmsigError(
                "camera intrinsics out of range",
                expected="fx, fy > 0 px and an image of at least 1 × 1 px",
                got=f"fx={self.fx}, fy={self.fy}, {self.width_px} × {self.height_px} px",
            )

    def vector(self) -> Array:
        """``(fx, fy, cx, cy, k1, k2, p1, p2, k3)`` (9,)."""
        return np.array([getattr(self, n) for n in INTRINSIC_NAMES], float)

    @classmethod
    def from_vector(cls, width_px: int, height_px: int, v: npt.ArrayLike) -> Intrinsics:
        values = np.asarray(v, float).reshape(-1)
        if values.shape != (len(INTRINSIC_NAMES),):
            raise ArmsigError(
                "camera intrinsics vector of the wrong length",
                expected=f"{len(INTRINSIC_NAMES)} values {', '.join(INTRINSIC_NAMES)}",
                got=f"{values.size} values",
            )
        named = dict(zip(INTRINSIC_NAMES, (float(x) for x in values), strict=True))
        return cls(int(width_px), int(height_px), **named)

    def camera_matrix(self) -> Array:
        """OpenCV's ``cameraMatrix`` (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def dist_coeffs(self) -> Array:
        """OpenCV's ``distCoeffs`` (5,): ``k1, k2, p1, p2, k3``."""
        return self.vector()[4:]

    def opencv(self) -> tuple[Array, Array]:
        """``(cameraMatrix, distCoeffs)`` as ``cv2.projectPoints`` takes them."""
        return self.camera_matrix(), self.dist_coeffs()

    @classmethod
    def from_opencv(
        cls, camera_matrix: npt.ArrayLike, dist_coeffs: npt.ArrayLike, width_px: int, height_px: int
    ) -> Intrinsics:
        """From OpenCV's ``cameraMatrix`` (3, 3) and ``distCoeffs`` (4, 5 or more values:
        the terms past ``k3`` must be zero, this model has none of them)."""
        K = np.asarray(camera_matrix, float)
        d = np.asarray(dist_coeffs, float).reshape(-1)
        if K.shape != (3, 3) or abs(K[0, 1]) > 0 or K[1, 0] or K[2, 0] or K[2, 1] or K[2, 2] != 1:
            raise ArmsigError(
                "not a pinhole camera matrix",
                expected="[[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)",
                got=str(K.tolist()),
            )
        if d.size < 4 or np.any(d[5:] != 0):
            raise ArmsigError(
                "distortion coefficients this model cannot hold",
                expected="OpenCV's k1, k2, p1, p2[, k3] (rational and prism terms zero)",
                got=str(d.tolist()),
                fix="calibrate with OpenCV's default flags (no CALIB_RATIONAL_MODEL)",
            )
        dist = np.zeros(5)
        dist[: min(5, d.size)] = d[:5]
        return cls.from_vector(width_px, height_px, [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist])

    def to_dict(self) -> dict[str, float | int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, float | int]) -> Intrinsics:
        return cls(int(d["width_px"]), int(d["height_px"]),
                   **{n: float(d.get(n, 0.0)) for n in INTRINSIC_NAMES})  # fmt: skip


def _normalized(p: Array) -> tuple[Array, Array, Array]:
    """``x'``, ``y'`` and ``Z`` (...) of points ``p`` (..., 3); NaN where ``Z`` <= 0."""
    Z = p[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        Z = np.where(Z > MIN_DEPTH, Z, np.nan)
        return p[..., 0] / Z, p[..., 1] / Z, Z


def project(p_cam: npt.ArrayLike, intrinsics: npt.ArrayLike) -> Array:
    """Pixels ``(u, v)`` (..., 2) of points ``p_cam`` (..., 3) in the optical frame, under
    the intrinsics vector (9,) (:data:`INTRINSIC_NAMES`); NaN behind the camera."""
    return project_with_jacobians(p_cam, intrinsics)[0]


def project_with_jacobians(
    p_cam: npt.ArrayLike, intrinsics: npt.ArrayLike
) -> tuple[Array, Array, Array]:
    """Pixels (..., 2), ``∂(u, v)/∂p`` (..., 2, 3) and ``∂(u, v)/∂intrinsics`` (..., 2, 9).

    Exact derivatives of the module docstring's equations (chain rule through
    ``(x', y')``, whose derivative in ``p`` is ``[[1/Z, 0, −x'/Z], [0, 1/Z, −y'/Z]]``).
    """
    p = np.asarray(p_cam, float)
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = np.asarray(intrinsics, float)
    x, y, Z = _normalized(p)
    r2 = x * x + y * y
    rho = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    d_rho = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # ∂ρ/∂r²
    xd = x * rho + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rho + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    uv = np.stack([fx * xd + cx, fy * yd + cy], axis=-1)
    # ∂(x'', y'')/∂(x', y'), with ∂r²/∂x' = 2x'
    dxd_dx = rho + 2.0 * x * x * d_rho + 2.0 * p1 * y + 6.0 * p2 * x
    dxd_dy = 2.0 * x * y * d_rho + 2.0 * p1 * x + 2.0 * p2 * y
    dyd_dx = 2.0 * x * y * d_rho + 2.0 * p1 * x + 2.0 * p2 * y
    dyd_dy = rho + 2.0 * y * y * d_rho + 6.0 * p1 * y + 2.0 * p2 * x
    D = np.stack(
        [np.stack([fx * dxd_dx, fx * dxd_dy], -1), np.stack([fy * dyd_dx, fy * dyd_dy], -1)], -2
    )  # (..., 2, 2): ∂(u, v)/∂(x', y')
    zero = np.zeros_like(Z)
    N = np.stack(
        [np.stack([1.0 / Z, zero, -x / Z], -1), np.stack([zero, 1.0 / Z, -y / Z], -1)], -2
    )  # (..., 2, 3): ∂(x', y')/∂p
    d_point = D @ N
    r4, r6, xy = r2 * r2, r2 * r2 * r2, x * y
    one = np.ones_like(Z)
    du = np.stack(
        [xd, zero, one, zero, fx * x * r2, fx * x * r4, fx * 2 * xy, fx * (r2 + 2 * x * x),
         fx * x * r6], -1,
    )  # fmt: skip
    dv = np.stack(
        [zero, yd, zero, one, fy * y * r2, fy * y * r4, fy * (r2 + 2 * y * y), fy * 2 * xy,
         fy * y * r6], -1,
    )  # fmt: skip
    return uv, d_point, np.stack([du, dv], axis=-2)
