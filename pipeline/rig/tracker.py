"""The simulated laser tracker: what a point-sensor rig records (``--sensor tracker``).

Noise model (docs/rig.md, "Laser tracker"): a tracker's maximum permissible error of a
point position, MPE = 15 µm + 6 µm/m · L (L: distance from the tracker; vendor data
sheets state it as ASME B89.4.19 / ISO 10360-10 MPE, e.g. Leica AT960 U_xyz), is
taken as a 2σ bound (vendors give typical errors as MPE / 2), so each coordinate
gets independent Gaussian noise of σ = (7.5 µm + 3 µm/m · L), isotropic, recorded
per point as ``sigma_cm``. The tracker sits at the sonic digitizer's origin (same
sensor frame), so a session's truth and plan are those of the sonic rig.

Nest: K reflectors per sweep (ids ``T1``..``TK``), T1 at the plan's nominal target,
the others at :data:`NEST_OFFSETS_CM` from it in the frame moving with the swept joint;
with ``nest_on_axis`` = i, sweep i's last reflector sits on joint i's true axis
(revolute), where it cannot show the joint's rotation (the features stage must not use
it). The tool and the validation configurations are measured at T1 (``tool_target``).
A pose set (``--poses N``: random configurations inside the limits whose tool is in
front of the tracker) measures the tool's nest, T1 at the tool and the others at the
same offsets in the last link's frame, at every pose. With a pose set the tool reflector
sits :data:`POSE_TOOL_OFFSET_CM` off the planned probe tip (off the flange axis).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.rig.plan import MeasurementPlan, tool_positions, visible
from pipeline.sensor.geometry import DigitizerGeometry

TOOL_TARGET = "T1"
#: Reflector offsets of a nest from T1, cm, in the frame moving with the swept joint:
#: a 6 cm triangle, the size of a three-SMR nest.
NEST_OFFSETS_CM = ((0.0, 0.0, 0.0), (0.0, 6.0, 0.0), (-3.0, 3.0, 4.0), (3.0, -3.0, 4.0))
MAX_TARGETS = len(NEST_OFFSETS_CM)
#: σ = a + b · L per coordinate: half the MPE of 15 µm + 6 µm/m (a 2σ bound).
SIGMA_A_CM = 0.00075
SIGMA_B_CM_PER_M = 0.0003
#: A session with a pose set mounts the tool reflector this far off the flange, in the
#: last D-H frame (cm): a reflector on the last joint's axis cannot show that axis's
#: direction, so the tool's orientation would not be identifiable from positions
#: (issue 26). 5 cm: the arm of a usual SMR tool adapter.
POSE_TOOL_OFFSET_CM = (5.0, 0.0, 0.0)


def pose_tool_local(probe_cm: tuple[float, float, float]) -> np.ndarray:
    """The tool reflector of a session with a pose set: the planned probe tip ``probe_cm``
    moved by :data:`POSE_TOOL_OFFSET_CM` (last D-H frame, cm)."""
    return np.array(probe_cm, float) + np.array(POSE_TOOL_OFFSET_CM)


#: A 6-D probe (``--six-d``, a T-Mac): the rotation vector (deg) of its frame in the last
#: D-H frame, as mounted (any rotation: the fit must find it), and the fixture's error
#: about it (deg) when not noiseless.
PROBE_ROTATION_DEG = (20.0, -35.0, 10.0)
PROBE_FIXTURE_DEG = 0.5
#: σ per rotation-vector component of a 6-D probe's orientation (deg): half the ±0.01°
#: of a Leica T-Mac's data sheet (its MPE taken as 2σ, as for the positions).
ORIENTATION_SIGMA_DEG = 0.005
#: Check configurations drawn per wanted one before giving up (most are visible).
_CHECK_DRAWS = 200


def target_ids(k: int) -> list[str]:
    return [f"T{i + 1}" for i in range(k)]


def rig_description() -> dict[str, Any]:
    """The ``/rig/description`` of the simulated tracker."""
    return {
        "sensor": "points",
        "instrument": "laser tracker (simulated by armsig)",
        "noise": {
            "model": "isotropic Gaussian per coordinate, sigma = a + b * distance (MPE / 2)",
            "source": "MPE 15 um + 6 um/m (ASME B89.4.19 / ISO 10360-10 laser tracker "
            "data sheets, e.g. Leica AT960), taken as 2 sigma",
            "sigma_a_cm": SIGMA_A_CM,
            "sigma_b_cm_per_m": SIGMA_B_CM_PER_M,
        },
    }


def nest_locals(
    target_local: np.ndarray, k: int, on_axis: bool, rng: np.random.Generator, fixture_cm: float
) -> np.ndarray:
    """True local positions (k, 3) of a sweep's nest around its true target T1."""
    out = target_local + np.array(NEST_OFFSETS_CM[:k], float)
    if k > 1:
        out[1:] += rng.normal(0, fixture_cm, (k - 1, 3))
    if on_axis:
        out[-1, :2] = 0.0  # on the swept joint's axis (the z axis of the moving frame)
    return out


def sigma_cm(p: np.ndarray) -> np.ndarray:
    """σ (m,) of each coordinate of points ``p`` (m, 3) by their distance from the tracker."""
    return SIGMA_A_CM + SIGMA_B_CM_PER_M * np.linalg.norm(p, axis=-1) / 100.0


def measure(
    p: np.ndarray, rng: np.random.Generator, noiseless: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Measured points (m, 3) and their recorded σ (m,)."""
    s = sigma_cm(p)
    if noiseless:
        return p.copy(), s
    return p + rng.normal(size=p.shape) * s[:, None], s


def check_configurations(
    n: int,
    limits: np.ndarray,
    chain: Any,
    sensor_from_base: np.ndarray,
    tool_local: np.ndarray,
    geometry: DigitizerGeometry,
    rng: np.random.Generator,
) -> np.ndarray:
    """``n`` random readings (n, joints) within the limits whose tool point is visible
    (in front of the wall, within the sensor's range), boundary units."""
    from pipeline.units import joints_to_internal

    pris = chain.prismatic
    out: list[np.ndarray] = []
    for _ in range(_CHECK_DRAWS):
        q = rng.uniform(limits[:, 0], limits[:, 1], (max(n, 1) * 4, len(limits)))
        p = tool_positions(chain, sensor_from_base, joints_to_internal(q, pris), tool_local)
        out.extend(q[visible(p, geometry)])
        if len(out) >= n:
            return np.array(out[:n])
    raise ValueError("no visible validation configuration")  # the plan's tool is visible


def plan_dict(
    plan: MeasurementPlan, k: int, n_check: int, n_poses: int = 0, sweeps: bool = True
) -> dict[str, Any]:
    """``plan`` as recorded by a point-sensor rig: one reading per configuration, the
    nest's target ids, the tool target, the validation configurations and the pose set
    (``n_poses`` configurations, the tool's nest of ``k`` targets at each); without
    ``sweeps`` the pose set alone (no joint sweep, no tool measurement)."""
    doc = plan.to_dict()
    doc["n_avg"] = 1
    for s in doc["sweeps"]:  # type: ignore[attr-defined]
        s["targets"] = target_ids(k)
    if not sweeps:
        doc["sweeps"], doc["order"] = [], []
    doc["tool_target"] = TOOL_TARGET
    if n_check:
        doc["check"] = {"n_points": n_check}
        doc["order"] = [*doc["order"], "check"]  # type: ignore[misc]
    if n_poses:
        doc["poses"] = {"n_points": n_poses, "targets": target_ids(k)}
        doc["order"] = [*doc["order"], "poses"]  # type: ignore[misc]
    return doc


def point_message(
    sweep: int | str, step: int, target: str, p: np.ndarray, s: float, exact: bool
) -> dict[str, Any]:
    """One ``/points`` payload; a noisy point is rounded to 1e-6 cm (10 nm, far below σ)."""
    xyz = [float(v) if exact else round(float(v), 6) for v in p]
    return {
        "sweep": sweep,
        "step": step,
        "target": target,
        "x_cm": xyz[0],
        "y_cm": xyz[1],
        "z_cm": xyz[2],
        "sigma_cm": float(s),
    }


def probe_rotation(rng: np.random.Generator, noiseless: bool) -> np.ndarray:
    """The true rotation (3, 3) of the 6-D probe in the last D-H frame."""
    from pipeline.kinematics.so3 import rotation_from_vector

    r = np.radians(np.array(PROBE_ROTATION_DEG))
    if not noiseless:
        r = r + np.radians(rng.normal(0.0, PROBE_FIXTURE_DEG, 3))
    return rotation_from_vector(r)


def measure_orientation(
    R: np.ndarray, rng: np.random.Generator, noiseless: bool
) -> list[dict[str, Any]]:
    """``/points`` fields of measured orientations ``R`` (m, 3, 3): the unit quaternion
    (w, x, y, z; w ≥ 0) of ``R · Exp(ε)``, ``ε ~ N(0, σ²I)`` unless noiseless, and σ."""
    from scipy.spatial.transform import Rotation

    from pipeline.kinematics.so3 import rotation_from_vector

    eps = (
        np.zeros((len(R), 3))
        if noiseless
        else rng.normal(0.0, np.radians(ORIENTATION_SIGMA_DEG), (len(R), 3))
    )
    q = Rotation.from_matrix(R @ rotation_from_vector(eps)).as_quat(scalar_first=True)
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    return [
        {
            "orientation_wxyz": [float(v) for v in row],
            "orientation_sigma_deg": ORIENTATION_SIGMA_DEG,
        }
        for row in q
    ]
