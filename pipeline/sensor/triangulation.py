"""Target position from three slant ranges (Section 6.3.1, (6.1)-(6.6), ERRATA.md).

:func:`triangulate` works in the frame of (6.1)-(6.6), that of
:func:`pipeline.sensor.geometry.microphones_from_distances`: ``C = 0``,
``B = (0, w_BC, 0)``, ``A = w_AC (sin θ, cos θ, 0)``, Z out of the wall. The target is
on the room side of the wall, so ``z = +sqrt(s3² − x² − y²)``.

:class:`Trilateration` applies it to microphones recorded anywhere in a sensor frame
whose Z points out of the wall (e.g. A at −X, a mirror of the thesis layout): it
solves in the (6.1) frame of the recorded A, B, C and maps the result back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.errors import ArmsigError

Array = npt.NDArray[np.float64]

#: ``z²`` comes from ``s3² − x² − y²``, a difference of terms as large as ``s3²``, so its
#: rounding error is some ulps of ``s1² + s2² + s3²`` (measured: below 1e-15 of it for
#: targets on the wall, 30-250 cm ranges). Negative ``z²`` within 1e-12 of that scale
#: (≤ 2e-7 cm² at 250 cm) is rounding and is clipped to 0. A real inconsistency of the
#: ranges by ε cm gives ``z² ≈ −2 s ε``, so the clip absorbs at most ε ≈ 4e-10 cm,
#: far below the 0.01 cm resolution; anything larger is an impossible range set (NaN).
_Z2_RTOL = 1e-12


def _cos_sin_theta(w_ab: float, w_bc: float, w_ac: float) -> tuple[float, float]:
    """``cos θ`` (6.5) and ``sin θ`` of the angle at C between C→B and C→A."""
    cos_t = (w_ac**2 + w_bc**2 - w_ab**2) / (2.0 * w_ac * w_bc)  # Eq. (6.5)
    if not (min(w_ab, w_bc, w_ac) > 0.0 and abs(cos_t) < 1.0):
        raise ArmsigError(
            "microphones A, B, C do not form a triangle",
            expected="positive distances w_AB, w_BC, w_AC obeying the strict triangle inequality",
            got=f"w_AB={w_ab}, w_BC={w_bc}, w_AC={w_ac} (cos θ = {cos_t})",
            fix="check the digitizer geometry in /rig/description",
        )
    sin_t = float(np.sqrt(1.0 - cos_t**2))  # Eq. (6.6), ERRATA form
    return float(cos_t), sin_t


def triangulate(s_abc: npt.ArrayLike, w_ab: float, w_bc: float, w_ac: float) -> Array:
    """Sensor-frame position of a target from its slant ranges to microphones A, B, C.

    Parameters
    ----------
    s_abc : array_like, shape (..., 3)
        Slant ranges ``s1, s2, s3`` (cm) from the target to microphones A, B, C.
    w_ab, w_bc, w_ac : float
        Distances (cm) between microphones A-B, B-C and A-C.

    Returns
    -------
    p : ndarray, shape (..., 3)
        Target ``(x, y, z)`` in cm with ``z ≥ 0``. A row is NaN where the three spheres
        do not meet (``s3² − x² − y² < 0`` beyond rounding) or an input range is NaN.

    Raises
    ------
    ArmsigError
        If ``s_abc`` does not end in an axis of 3, or A, B, C are not a triangle.
    """
    s = np.asarray(s_abc, float)
    if s.ndim < 1 or s.shape[-1] != 3:
        raise ArmsigError(
            "triangulate needs three slant ranges per target",
            expected="s_abc of shape (..., 3) (ranges to A, B, C)",
            got=f"shape {s.shape}",
            fix="pass raw[..., 4, :3] or the compensated ranges",
        )
    cos_t, sin_t = _cos_sin_theta(w_ab, w_bc, w_ac)
    s1, s2, s3 = s[..., 0], s[..., 1], s[..., 2]
    y = (w_bc**2 + s3**2 - s2**2) / (2.0 * w_bc)  # Eq. (6.2)
    r = (w_ac**2 + s3**2 - s1**2) / (2.0 * w_ac)  # Eq. (6.4)
    x = (r - y * cos_t) / sin_t  # Eq. (6.1), ERRATA form
    z2 = s3**2 - x**2 - y**2  # Eq. (6.3), under the root
    rounding = -_Z2_RTOL * (s1**2 + s2**2 + s3**2)
    ok = z2 >= rounding  # False for NaN too
    z = np.sqrt(np.where(ok, np.maximum(z2, 0.0), np.nan))  # Eq. (6.3), z ≥ 0
    p = np.stack([x, y, z], axis=-1)
    p[~ok] = np.nan
    return p


#: The wall (the A-B-C plane) must face the sensor Z axis within 45°: Z then tells
#: the room side unambiguously; "Z out of the wall" is the contract's frame.
_WALL_COS_MIN = np.cos(np.deg2rad(45.0))


@dataclass(frozen=True)
class Trilateration:
    """(6.1)-(6.6) for microphones A, B, C as recorded, positions in the recording's frame.

    Attributes
    ----------
    w_ab, w_bc, w_ac : float
        Microphone distances (cm).
    origin : ndarray, shape (3,)
        Microphone C.
    axes : ndarray, shape (3, 3), or None
        Columns: the (6.1) frame's X (toward A's side of C-B), Y (toward B) and Z
        (toward the room, the recording's +Z side) in the recording's frame; a
        reflection when A lies at −X. None when the two frames coincide.
    """

    w_ab: float
    w_bc: float
    w_ac: float
    origin: Array
    axes: Array | None

    @classmethod
    def from_microphones(cls, abc: npt.ArrayLike) -> Trilateration:
        """From A, B, C (3, 3) in the sensor frame (cm); raises :class:`ArmsigError`
        when they are no triangle or their plane does not face the Z axis."""
        a, b, c = np.asarray(abc, float)
        w_ab, w_bc, w_ac = (float(np.linalg.norm(u - v)) for u, v in ((a, b), (b, c), (a, c)))
        _cos_sin_theta(w_ab, w_bc, w_ac)  # a triangle, or the error
        ey = (b - c) / w_bc
        v = (a - c) - ((a - c) @ ey) * ey
        ex = v / np.linalg.norm(v)
        normal = np.cross(ex, ey)
        if not abs(normal[2]) >= _WALL_COS_MIN:
            raise ArmsigError(
                "the microphones' wall does not face the sensor Z axis",
                expected="A, B, C in a plane within 45° of the sensor X-Y plane "
                "(Z out of the wall)",
                got=f"plane normal {np.round(normal, 4).tolist()}",
                fix="record the microphones in the sensor frame of "
                "schemas/mcap/rig_description.json",
            )
        axes = np.column_stack([ex, ey, normal * np.sign(normal[2])])
        same = np.array_equal(axes, np.eye(3)) and not c.any()
        return cls(w_ab, w_bc, w_ac, c, None if same else axes)

    def __call__(self, s_abc: npt.ArrayLike) -> Array:
        """Positions (..., 3) from ranges ``s_abc`` (..., 3) to A, B, C, as :func:`triangulate`."""
        p = triangulate(s_abc, self.w_ab, self.w_bc, self.w_ac)
        if self.axes is None:
            return p
        return np.asarray(self.origin + p @ self.axes.T, float)
