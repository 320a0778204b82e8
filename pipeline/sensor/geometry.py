"""Geometry of the sonic digitizer (Section 6.3.1, Figure 6-4, Appendix E.1).

Sensor frame: origin at microphone C's acoustic zero, Y toward microphone B,
Z out of the wall (the A-B-C plane), X = Y × Z. The line A-C is level, so the
"up" direction in the sensor frame is the in-plane unit vector perpendicular
to C→A that points toward B.

Microphone D and the calibration rods are not dimensioned in the thesis
(Figure 6-4 is lost to OCR). armsig's defaults, used by the simulator and
recorded in every session's ``/rig/description`` so the pipeline never
guesses them:

- D lies in the wall plane below the midpoint of A-C, :data:`D_DROP_CM` below the
  A-C line ("D low").
- Each rod is level and collinear with its microphone (E.1): sparker 1 (3) sits
  :data:`ROD_NEAR_CM` from B (D) and sparker 2 (4) a further 100 cm along the same
  level line, which leaves the wall at :data:`ROD_ANGLE_DEG` toward the room.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.sensor.triangulation import Trilateration

W_AB_CM = 143.0  # Section 6.3.1
W_BC_CM = 143.0
W_AC_CM = 203.0
ROD_LENGTH_CM = 100.0  # Appendix E.1: calibrated sparker spacing
RANGE_MIN_CM = 30.0  # Section 6.3.1: measurable slant ranges
RANGE_MAX_CM = 250.0
RESOLUTION_CM = 0.01
NOMINAL_TEMPERATURE_F = 70.0  # Section 6.3.1: internal speed of sound at 70 °F
D_DROP_CM = 40.0
ROD_NEAR_CM = 40.0
ROD_ANGLE_DEG = 45.0
MICROPHONES = ("A", "B", "C", "D")
#: B and D must differ in height by this much: compensation draws the speed of sound
#: through their two heights (B-3), and over the ~150 cm of the workspace a 1 cm base
#: already magnifies one count (0.01 cm) of rod-range rounding 150-fold.
MIN_ROD_HEIGHT_GAP_CM = 1.0
#: A rod sparker may sit this far off its microphone's level line, or its spacing off
#: ``rod_length_cm``: 0.1 cm of height changes the speed ratio by ~1e-6 (gradients of
#: ~1e-5 per cm, Appendix E); a wrong layout (swapped sparkers, a rod at the other
#: microphone) is off by tens of cm.
ROD_TOL_CM = 0.1


def speed_of_sound_cm_s(temperature_f: np.ndarray | float) -> np.ndarray:
    """Speed of sound in dry air, ``331.3 · sqrt(1 + T/273.15)`` m/s (ERRATA.md), in cm/s.

    Parameters
    ----------
    temperature_f : array_like, shape (...)
        Air temperature in °F.
    """
    t_c = (np.asarray(temperature_f, float) - 32.0) * 5.0 / 9.0
    return 33130.0 * np.sqrt(1.0 + t_c / 273.15)


@dataclass(frozen=True)
class DigitizerGeometry:
    """Positions of the fixed microphones and calibration sparkers, sensor frame, cm.

    Attributes
    ----------
    microphones : ndarray, shape (4, 3)
        A, B, C, D acoustic zeros.
    rod_sparkers : ndarray, shape (4, 3)
        Sparkers 1, 2 (upper rod, level with B) and 3, 4 (lower rod, level with D).
    rod_length_cm : float
        Calibrated distance between the sparkers of one rod (E.1).
    nominal_speed_cm_s : float
        ``S*``, the digitizer's internal speed of sound.
    range_min_cm, range_max_cm, resolution_cm : float
        Measurable slant ranges and their quantization.
    """

    microphones: np.ndarray
    rod_sparkers: np.ndarray
    rod_length_cm: float = ROD_LENGTH_CM
    nominal_speed_cm_s: float = float(speed_of_sound_cm_s(NOMINAL_TEMPERATURE_F))
    range_min_cm: float = RANGE_MIN_CM
    range_max_cm: float = RANGE_MAX_CM
    resolution_cm: float = RESOLUTION_CM

    @property
    def w_ab(self) -> float:
        return float(np.linalg.norm(self.microphones[0] - self.microphones[1]))

    @property
    def w_bc(self) -> float:
        return float(np.linalg.norm(self.microphones[1] - self.microphones[2]))

    @property
    def w_ac(self) -> float:
        return float(np.linalg.norm(self.microphones[0] - self.microphones[2]))

    @property
    def up(self) -> np.ndarray:
        """Unit vertical (against gravity) in the sensor frame, shape (3,)."""
        return up_direction(self.microphones)

    def height(self, p: np.ndarray) -> np.ndarray:
        """Height above microphone C of points ``p`` (..., 3) in cm, shape (...)."""
        return np.asarray(p, float) @ self.up

    def to_dict(self) -> dict[str, object]:
        """JSON-ready description (the ``/rig/description`` payload's geometry)."""
        return {
            "microphones_cm": {m: self.microphones[k].tolist() for k, m in enumerate(MICROPHONES)},
            "rod_sparkers_cm": {str(k + 1): self.rod_sparkers[k].tolist() for k in range(4)},
            "rod_length_cm": self.rod_length_cm,
            "nominal_speed_cm_s": self.nominal_speed_cm_s,
            "range_min_cm": self.range_min_cm,
            "range_max_cm": self.range_max_cm,
            "resolution_cm": self.resolution_cm,
        }

    @classmethod
    def from_dict(cls, d: dict[str, object], source: str = "/rig/description") -> DigitizerGeometry:
        """Inverse of :meth:`to_dict`; raises :class:`ArmsigError` naming a missing key."""
        try:
            mics = d["microphones_cm"]
            rods = d["rod_sparkers_cm"]
            return cls(
                microphones=np.array([mics[m] for m in MICROPHONES], float),  # type: ignore[index]
                rod_sparkers=np.array([rods[str(k)] for k in range(1, 5)], float),  # type: ignore[index]
                rod_length_cm=float(d["rod_length_cm"]),  # type: ignore[arg-type]
                nominal_speed_cm_s=float(d["nominal_speed_cm_s"]),  # type: ignore[arg-type]
                range_min_cm=float(d["range_min_cm"]),  # type: ignore[arg-type]
                range_max_cm=float(d["range_max_cm"]),  # type: ignore[arg-type]
                resolution_cm=float(d["resolution_cm"]),  # type: ignore[arg-type]
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ArmsigError(
                f"{source}: digitizer geometry is incomplete",
                expected="microphones_cm A-D, rod_sparkers_cm 1-4, rod_length_cm, "
                "nominal_speed_cm_s, range_min_cm, range_max_cm, resolution_cm",
                got=f"{type(exc).__name__}: {exc}",
                fix="re-record the session or repair its /rig/description message",
            ) from exc


def check_geometry(g: DigitizerGeometry, source: str = "/rig/description") -> None:
    """Raise :class:`ArmsigError` when ``g`` is not a layout the pipeline can use as recorded.

    Checks: a range window; A, B, C a triangle facing the sensor Z axis
    (:class:`~pipeline.sensor.triangulation.Trilateration`); B and D at heights
    :data:`MIN_ROD_HEIGHT_GAP_CM` apart; sparkers 1, 2 (3, 4) on the level line
    through B (D), within :data:`ROD_TOL_CM`, ``rod_length_cm`` apart, 1 (3) the near one.
    """
    fix = "repair the rig's /rig/description (schemas/mcap/rig_description.json)"
    if not g.range_min_cm < g.range_max_cm:
        raise ArmsigError(
            f"{source}: empty range window",
            expected="range_min_cm < range_max_cm",
            got=f"{g.range_min_cm:g} and {g.range_max_cm:g} cm",
            fix=fix,
        )
    try:
        Trilateration.from_microphones(g.microphones[:3])
    except ArmsigError as exc:
        raise ArmsigError(
            f"{source}: {exc.what}", expected=exc.expected, got=exc.got, fix=fix
        ) from exc
    h = g.height(g.microphones)
    if not abs(h[3] - h[1]) >= MIN_ROD_HEIGHT_GAP_CM:
        raise ArmsigError(
            f"{source}: microphones B and D are at the same height",
            expected=f"heights at least {MIN_ROD_HEIGHT_GAP_CM:g} cm apart (Appendix E)",
            got=f"B at {h[1]:.4g} cm, D at {h[3]:.4g} cm above C",
            fix=fix,
        )
    for near, far, mic in ((0, 1, 1), (2, 3, 3)):
        broken = _rod_rule(g, near, far, mic)
        if broken is not None:
            rule, got = broken
            raise ArmsigError(
                f"{source}: sparkers {near + 1} and {far + 1} break the rod rule of "
                f"microphone {MICROPHONES[mic]} (E.1): {rule}",
                expected=f"sparker {near + 1} nearer, sparker {far + 1} rod_length_cm "
                f"({g.rod_length_cm:g}) farther on the level line through "
                f"{MICROPHONES[mic]}, within {ROD_TOL_CM:g} cm",
                got=got,
                fix=fix,
            )


def _rod_rule(g: DigitizerGeometry, near: int, far: int, mic: int) -> tuple[str, str] | None:
    """The first rule of (E.1) that rod sparkers ``near``, ``far`` (0-based) of microphone
    ``mic`` break, as (the rule, what was found); None when they keep every one."""
    m, p1, p2 = g.microphones[mic], g.rod_sparkers[near], g.rod_sparkers[far]
    d1, d2 = p1 - m, p2 - m
    along = d2 / np.linalg.norm(d2)
    off_line = float(np.linalg.norm(d1 - (d1 @ along) * along))
    h = g.height(np.array([p1, p2]))
    off_level = float(np.max(np.abs(h - g.height(m[None])[0])))
    spacing = float(np.linalg.norm(p2 - p1))
    a, b, mn = near + 1, far + 1, MICROPHONES[mic]
    if off_level > ROD_TOL_CM:
        return (
            f"the rod must be level with microphone {mn}",
            f"a sparker {off_level:.3g} cm above or below it",
        )
    if off_line > ROD_TOL_CM or not np.isfinite(off_line):
        return (
            f"sparker {a} must be on the line from microphone {mn} through sparker {b}",
            f"{off_line:.3g} cm off it",
        )
    if not 0.0 < d1 @ along < np.linalg.norm(d2):
        return (
            f"sparker {a} must be the near one, between microphone {mn} and sparker {b}",
            f"sparker {a} {np.linalg.norm(d1):.6g} cm from {mn}, sparker {b} "
            f"{np.linalg.norm(d2):.6g} cm (rods numbered the other way?)",
        )
    if abs(spacing - g.rod_length_cm) > ROD_TOL_CM:
        return (
            f"sparkers {a} and {b} must be rod_length_cm apart",
            f"{spacing:.6g} cm apart",
        )
    return None


def up_direction(microphones: np.ndarray) -> np.ndarray:
    """In-plane unit vector perpendicular to C→A, toward B (A-C is level), shape (3,)."""
    a, b, c = (np.asarray(microphones[k], float) for k in range(3))
    h = (a - c) / np.linalg.norm(a - c)
    v = (b - c) - ((b - c) @ h) * h
    return v / np.linalg.norm(v)


def microphones_from_distances(
    w_ab: float = W_AB_CM, w_bc: float = W_BC_CM, w_ac: float = W_AC_CM
) -> np.ndarray:
    """A, B, C in the sensor frame from the three microphone distances, shape (3, 3).

    ``C = 0``, ``B = (0, w_BC, 0)``, ``A = w_AC (sin θ, cos θ, 0)`` with θ the angle at
    C from (6.5); this is the frame in which (6.1)-(6.4) hold.
    """
    cos_t = (w_ac**2 + w_bc**2 - w_ab**2) / (2.0 * w_ac * w_bc)  # Eq. (6.5)
    sin_t = np.sqrt(1.0 - cos_t**2)
    return np.array([[w_ac * sin_t, w_ac * cos_t, 0.0], [0.0, w_bc, 0.0], [0.0, 0.0, 0.0]])


def default_geometry(
    w_ab: float = W_AB_CM, w_bc: float = W_BC_CM, w_ac: float = W_AC_CM
) -> DigitizerGeometry:
    """The armsig default digitizer layout (see the module docstring)."""
    abc = microphones_from_distances(w_ab, w_bc, w_ac)
    a, b, c = abc
    up = up_direction(abc)
    level = (a - c) / np.linalg.norm(a - c)
    d = c + 0.5 * (a - c) - D_DROP_CM * up
    ang = np.deg2rad(ROD_ANGLE_DEG)
    rod_dir = np.cos(ang) * level + np.sin(ang) * np.array([0.0, 0.0, 1.0])
    rods = np.array(
        [
            b + ROD_NEAR_CM * rod_dir,
            b + (ROD_NEAR_CM + ROD_LENGTH_CM) * rod_dir,
            d + ROD_NEAR_CM * rod_dir,
            d + (ROD_NEAR_CM + ROD_LENGTH_CM) * rod_dir,
        ]
    )
    return DigitizerGeometry(microphones=np.vstack([abc, d]), rod_sparkers=rods)
