"""Where the targets go and how the joints are swept (Section 6.4, Figure 6-7, App. F.2).

Target ``i`` sits on link ``i`` at ``(R_i, 0, z_i)`` in the frame that follows
joint ``i``'s motion (``F_{i-1} · Rot(z, q_i)``), which is (F.5)-(F.6): the
``Rot(x, rx_i)`` of Offset_i turns the sparker, not its position. The Puma uses
the radii of Table 6-1 and the offsets ``z_i`` of Table F-1; other robots a
default radius.

The thesis's signature configuration (155, 179, 178, 0, 0, 0)° is in the Puma
controller's joint convention, not in this D-H zero, so it cannot be copied.
The planner instead searches the design model (as an operator would with a
teach pendant) for a signature configuration where every target stays within
the digitizer's range and in front of the wall over the widest sweep the joint
limits allow, and where the tool probe is visible. This is documented in
``docs/rig.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import SerialChain, joint_motion, link_frames
from pipeline.kinematics.transforms import chain_product, rot_x, rot_z, trans
from pipeline.robots.description import RobotDescription
from pipeline.sensor.geometry import DigitizerGeometry
from pipeline.units import joints_to_internal

TABLE_6_1_RADII_CM = (40.87, 41.62, 43.71, 33.30, 45.13, 33.30)
TABLE_F_1_Z_CM = (20.300, 33.309, 18.500, 53.531, 3.200, 10.225)
DEFAULT_RADIUS_CM = 30.0
PROBE_LENGTH_CM = 15.0  # evaluation tool: a pointed probe on the flange axis
#: Keep planned ranges this far inside the 30-250 cm limits and targets this far in
#: front of the wall, so that manufacturing errors (mm) never push a target out.
RANGE_MARGIN_CM = 5.0
WALL_MARGIN_CM = 10.0
MAX_SWEEP_DEG = 300.0
MIN_SWEEP_DEG = 180.0  # (B-3) wants at least 180° of travel
SWEEP_END_MARGIN_DEG = 3.0


@dataclass(frozen=True)
class Sweep:
    """One target's sweep: joint ``joint`` (1-based) indexed over ``q_values``.

    ``q_values`` (N_i,) are in deg (revolute) or cm (prismatic);
    ``target_local_cm`` (3,) is the nominal target position on link ``joint``.
    """

    joint: int
    target_local_cm: tuple[float, float, float]
    q_values: tuple[float, ...]


@dataclass(frozen=True)
class MeasurementPlan:
    """The whole session plan: order n..1, then the tool probe at q^s."""

    signature_q: tuple[float, ...]
    sweeps: tuple[Sweep, ...]
    n_avg: int
    tool_local_cm: tuple[float, float, float]

    def to_dict(self) -> dict[str, object]:
        return {
            "signature_q": list(self.signature_q),
            "n_avg": self.n_avg,
            "order": [s.joint for s in self.sweeps] + ["tool"],
            "sweeps": [
                {
                    "joint": s.joint,
                    "target_local_cm": list(s.target_local_cm),
                    "nominal_radius_cm": float(np.hypot(*s.target_local_cm[:2])),
                    "n_points": len(s.q_values),
                    "q_first": s.q_values[0],
                    "q_last": s.q_values[-1],
                }
                for s in self.sweeps
            ],
            "tool_local_cm": list(self.tool_local_cm),
        }


def wall_placement(shoulder_height_cm: float) -> np.ndarray:
    """Sensor-to-base transform of (F.3) for a robot whose shoulder is this high.

    (F.3) ends in ``Trans(0, −20.30, −67.183)`` to a base 67.183 cm below the
    shoulder (F.4). armsig's bases are the design models' mounting surfaces, so
    the last factor is ``Trans(0, −20.30, 0) · Trans(0, 0, −shoulder_height)``.
    """
    d = np.deg2rad
    return chain_product(
        trans(106.16, 56.98, 87.82),
        rot_z(d(45.0)),
        rot_x(d(-90.0)),
        rot_z(d(155.0)),
        trans(0.0, -20.30, 0.0),
        trans(0.0, 0.0, -shoulder_height_cm),
    )


def default_sensor_from_base(robot: RobotDescription) -> np.ndarray:
    """(F.3) with the robot's shoulder height: 67.4 cm for the Puma (Section 7.2.2),
    the first D-H ``d`` for other robots."""
    return wall_placement(robot.joints[0].dh.d_cm)


def nominal_target_local(robot: RobotDescription) -> list[tuple[float, float, float]]:
    """Nominal target positions on each link (cm)."""
    if robot.name == "puma560":
        return [(r, 0.0, z) for r, z in zip(TABLE_6_1_RADII_CM, TABLE_F_1_Z_CM, strict=True)]
    return [(DEFAULT_RADIUS_CM, 0.0, 0.0)] * robot.n_joints


def target_positions(
    chain: SerialChain, sensor_from_base: np.ndarray, q: np.ndarray, joint: int, local: np.ndarray
) -> np.ndarray:
    """Sensor-frame positions of target ``joint`` (1-based) at joint readings ``q`` (..., n).

    ``local`` (..., 3) is the target in the frame ``F_{joint-1} · M_joint(q)``.
    """
    F = link_frames(chain, q)[..., joint - 1, :, :]
    M = joint_motion(chain, q)[..., joint - 1, :, :]
    p = np.concatenate([np.asarray(local, float), np.ones((*np.shape(local)[:-1], 1))], axis=-1)
    return (sensor_from_base @ F @ M @ p[..., None])[..., :3, 0]


def tool_positions(
    chain: SerialChain, sensor_from_base: np.ndarray, q: np.ndarray, local: np.ndarray
) -> np.ndarray:
    """Sensor-frame positions of the probe tip ``local`` (3,) in the flange frame."""
    F = link_frames(chain, q)[..., -2, :, :]
    return (sensor_from_base @ F @ np.append(local, 1.0))[..., :3]


def visible(p: np.ndarray, geometry: DigitizerGeometry) -> np.ndarray:
    """Whether targets ``p`` (..., 3) are safely measurable by microphones A, B, C."""
    dist = np.linalg.norm(p[..., None, :] - geometry.microphones[:3], axis=-1)
    return (
        (dist.min(-1) > geometry.range_min_cm + RANGE_MARGIN_CM)
        & (dist.max(-1) < geometry.range_max_cm - RANGE_MARGIN_CM)
        & (p[..., 2] > WALL_MARGIN_CM)
    )


def _longest_run(ok: np.ndarray) -> tuple[int, int]:
    """Start and length of the longest run of True in a 1-D mask."""
    best, best_start, start = 0, 0, None
    for k, v in enumerate(np.append(ok, False)):
        if v and start is None:
            start = k
        elif not v and start is not None:
            if k - start > best:
                best, best_start = k - start, start
            start = None
    return best_start, best


def plan_measurements(
    robot: RobotDescription,
    geometry: DigitizerGeometry,
    sensor_from_base: np.ndarray,
    n_points: int = 100,
    n_avg: int = 10,
    candidates: int = 400,
    seed: int = 560,
    max_sweep_deg: float = MAX_SWEEP_DEG,
) -> MeasurementPlan:
    """Choose q^s and the sweep of every joint on the design model.

    ``max_sweep_deg`` caps every revolute sweep (default 300°); a smaller cap (say
    90°) records a deliberately short sweep, as in the (B-3) experiments.

    Raises
    ------
    ArmsigError
        When no signature configuration keeps every target visible over at least
        180° (revolute) or half the travel (prismatic).
    """
    chain = robot.design_chain()
    lim = robot.limits
    pris = robot.prismatic
    locals_ = [np.array(v) for v in nominal_target_local(robot)]
    rng = np.random.default_rng(seed)
    cand = rng.uniform(lim[:, 0], lim[:, 1], (candidates, robot.n_joints))
    step = np.where(pris, 1.0, 2.0)  # coarse search grid: 2° or 1 cm
    tool_local = np.array([0.0, 0.0, PROBE_LENGTH_CM])
    tool_ok = visible(
        tool_positions(chain, sensor_from_base, joints_to_internal(cand, pris), tool_local),
        geometry,
    )
    arcs = np.zeros((candidates, robot.n_joints))
    for i in range(robot.n_joints):
        grid = np.arange(lim[i, 0], lim[i, 1] + 1e-9, step[i])
        q = np.repeat(cand[:, None, :], len(grid), axis=1)
        q[:, :, i] = grid
        ok = visible(
            target_positions(
                chain, sensor_from_base, joints_to_internal(q, pris), i + 1, locals_[i]
            ),
            geometry,
        )
        arcs[:, i] = [_longest_run(row)[1] * step[i] for row in ok]
    travel = lim[:, 1] - lim[:, 0]
    # A joint whose whole travel is under 180° (B-3 then warns) needs all of it.
    need = np.where(
        pris,
        0.5 * travel,
        np.minimum(min(MIN_SWEEP_DEG, max_sweep_deg) + 2 * SWEEP_END_MARGIN_DEG, travel - step),
    )
    feasible = tool_ok & np.all(arcs >= need, axis=1)
    if not feasible.any():
        worst = int(np.argmin(arcs.max(axis=0) - need))
        raise ArmsigError(
            f"{robot.name}: no signature configuration keeps every target visible",
            expected=f"a visible sweep of at least {need[worst]:g} on joint {worst + 1}",
            got=f"at most {arcs[:, worst].max():g}",
            fix="move the sensor (sensor_from_base) or change the target radii",
        )
    capped = np.minimum(arcs, np.where(pris, np.inf, max_sweep_deg))
    score = np.where(feasible, np.sum(capped / (lim[:, 1] - lim[:, 0]), axis=1), -np.inf)
    qs = cand[int(np.argmax(score))]
    sweeps = []
    for i in range(robot.n_joints):
        fine = 0.1 if pris[i] else 0.5
        grid = np.arange(lim[i, 0], lim[i, 1] + 1e-9, fine)
        q = np.tile(qs, (len(grid), 1))
        q[:, i] = grid
        ok = visible(
            target_positions(
                chain, sensor_from_base, joints_to_internal(q, pris), i + 1, locals_[i]
            ),
            geometry,
        )
        start, length = _longest_run(ok)
        lo, hi = grid[start], grid[start + length - 1]
        margin = 0.5 if pris[i] else SWEEP_END_MARGIN_DEG
        lo, hi = lo + margin, hi - margin
        if not pris[i] and hi - lo > max_sweep_deg:
            mid = 0.5 * (lo + hi)
            lo, hi = mid - max_sweep_deg / 2, mid + max_sweep_deg / 2
        values = np.round(np.linspace(lo, hi, n_points), 6)
        x, y, z = (float(v) for v in locals_[i])
        sweeps.append(Sweep(i + 1, (x, y, z), tuple(map(float, values))))
    return MeasurementPlan(
        signature_q=tuple(float(v) for v in np.round(qs, 3)),
        sweeps=tuple(reversed(sweeps)),  # Figure 6-7: target n first, target 1 last
        n_avg=n_avg,
        tool_local_cm=(0.0, 0.0, PROBE_LENGTH_CM),
    )
