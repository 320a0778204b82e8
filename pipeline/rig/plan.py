"""Where the targets go and how the joints are swept (Section 6.4, Figure 6-7, App. F.2).

Target ``i`` sits on link ``i`` at ``(R_i, 0, z_i)`` in the frame that follows
joint ``i``'s motion (``F_{i-1} · Rot(z, q_i)``), which is (F.5)-(F.6): the
``Rot(x, rx_i)`` of Offset_i turns the sparker, not its position. The Puma uses
the radii of Table 6-1 and the offsets ``z_i`` of Table F-1; other robots
:data:`DEFAULT_RADIUS_CM`. When a joint has no visible sweep with its first
radius, the planner falls back, joint by joint, to the other radii of
:data:`RADIUS_FALLBACKS_CM` (larger first: Section 7.4.5, a larger radius gives
better features), and when none works it raises an error naming the joint, why
its targets are lost (too near, too far, behind the wall) and what to change.

The thesis's signature configuration (155, 179, 178, 0, 0, 0)° is in the Puma
controller's joint convention, not in this D-H zero, so it cannot be copied.
The planner instead searches the design model (as an operator would with a
teach pendant) for a signature configuration where every target stays within
the digitizer's range and in front of the wall over the widest sweep the joint
limits allow, and where the tool probe is visible. This is documented in
``docs/rig.md``.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
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
#: Radii tried, in this order, for a joint whose first radius has no visible sweep.
RADIUS_FALLBACKS_CM = (40.0, 30.0, 20.0, 45.0, 15.0, 10.0)
PROBE_LENGTH_CM = 15.0  # evaluation tool: a pointed probe on the flange axis
#: Keep planned ranges this far inside the 30-250 cm limits and targets this far in
#: front of the wall, so that manufacturing errors (mm) never push a target out.
RANGE_MARGIN_CM = 5.0
WALL_MARGIN_CM = 10.0
#: Memory for one block of the candidate search (its largest array; a few of them live
#: at once): long joint travels are searched in blocks of candidates.
_SEARCH_BYTES = 1 << 27  # 128 MiB
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
    """First-choice target positions on each link (cm)."""
    if robot.name == "puma560":
        return [(r, 0.0, z) for r, z in zip(TABLE_6_1_RADII_CM, TABLE_F_1_Z_CM, strict=True)]
    return [(DEFAULT_RADIUS_CM, 0.0, 0.0)] * robot.n_joints


def target_candidates(robot: RobotDescription) -> np.ndarray:
    """Target positions (n, K, 3) tried on each link, in order of preference (cm).

    The first is :func:`nominal_target_local`; the others keep its offset along the
    joint axis and take the radii of :data:`RADIUS_FALLBACKS_CM`.
    """
    out = []
    for r0, _, z in nominal_target_local(robot):
        radii = [r0, *(r for r in RADIUS_FALLBACKS_CM if r != r0)]
        out.append([(r, 0.0, z) for r in radii])
    return np.array(out, float)


def target_frames(
    chain: SerialChain, sensor_from_base: np.ndarray, q: np.ndarray, joint: int
) -> np.ndarray:
    """Sensor-frame poses (..., 4, 4) of the frame ``F_{joint-1} · M_joint(q)`` that
    carries target ``joint`` (1-based), at joint readings ``q`` (..., n)."""
    F = link_frames(chain, q)[..., joint - 1, :, :]
    M = joint_motion(chain, q)[..., joint - 1, :, :]
    out: np.ndarray = sensor_from_base @ F @ M
    return out


def target_positions(
    chain: SerialChain, sensor_from_base: np.ndarray, q: np.ndarray, joint: int, local: np.ndarray
) -> np.ndarray:
    """Sensor-frame positions of target ``joint`` (1-based) at joint readings ``q`` (..., n).

    ``local`` (..., 3) is the target in the frame ``F_{joint-1} · M_joint(q)``.
    """
    return points_in_frames(target_frames(chain, sensor_from_base, q, joint), local)


def points_in_frames(T: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Points ``local`` (..., 3) given in frames ``T`` (..., 4, 4), in ``T``'s parent
    frame (..., 3); the two shapes broadcast."""
    return (T[..., :3, :3] @ np.asarray(local, float)[..., None])[..., 0] + T[..., :3, 3]


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


def _longest_runs(ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and length of the longest run of True along the last axis of a mask.

    Returns integer arrays of shape ``ok.shape[:-1]`` (start 0 and length 0 when
    there is no True).
    """
    count = np.cumsum(ok, axis=-1)
    # Run length ending at each position: the count minus the count at the last False.
    run = count - np.maximum.accumulate(np.where(ok, 0, count), axis=-1)
    end = np.argmax(run, axis=-1)
    length = np.take_along_axis(run, end[..., None], axis=-1)[..., 0]
    return end - length + 1, length


def _why_lost(chunks: Iterable[np.ndarray], geometry: DigitizerGeometry) -> str:
    """Which visibility condition the targets (chunks of positions (..., 3)) break most often."""
    lo, hi = geometry.range_min_cm + RANGE_MARGIN_CM, geometry.range_max_cm - RANGE_MARGIN_CM
    counts = {
        f"nearer than {lo:g} cm to a microphone": 0,
        f"farther than {hi:g} cm from a microphone": 0,
        f"less than {WALL_MARGIN_CM:g} cm in front of the wall": 0,
    }
    for p in chunks:
        dist = np.linalg.norm(p[..., None, :] - geometry.microphones[:3], axis=-1)
        broken = (dist.min(-1) <= lo, dist.max(-1) >= hi, p[..., 2] <= WALL_MARGIN_CM)
        for key, mask in zip(counts, broken, strict=True):
            counts[key] += int(mask.sum())
    return max(counts, key=lambda k: counts[k])


def plan_measurements(
    robot: RobotDescription,
    geometry: DigitizerGeometry,
    sensor_from_base: np.ndarray,
    n_points: int = 100,
    n_avg: int = 10,
    candidates: int = 400,
    seed: int = 560,
    max_sweep_deg: float = MAX_SWEEP_DEG,
    target_local: list[tuple[float, float, float]] | None = None,
) -> MeasurementPlan:
    """Choose q^s, the target of every link and the sweep of every joint on the design model.

    ``max_sweep_deg`` caps every revolute sweep (default 300°); a smaller cap (say
    90°) records a deliberately short sweep, as in the (B-3) experiments.
    ``target_local`` replaces :func:`target_candidates` by exactly these targets,
    with no fallback radius (the Monte-Carlo radius study of Section 7.4.5 puts
    every target at ``R_nom``).

    Raises
    ------
    ArmsigError
        When no signature configuration keeps every target visible over at least
        180° (revolute; all of a shorter travel) or half the travel (prismatic),
        with the tool probe visible; the message names the joint and the reason.
    """
    chain = robot.design_chain()
    n = robot.n_joints
    lim = robot.limits
    pris = robot.prismatic
    options = (
        np.array(target_local, float)[:, None, :]
        if target_local is not None
        else target_candidates(robot)
    )  # (n, K, 3)
    rng = np.random.default_rng(seed)
    cand = rng.uniform(lim[:, 0], lim[:, 1], (candidates, n))
    step = np.where(pris, 1.0, 2.0)  # coarse search grid: 2° or 1 cm
    tool_local = np.array([0.0, 0.0, PROBE_LENGTH_CM])
    tool_ok = visible(
        tool_positions(chain, sensor_from_base, joints_to_internal(cand, pris), tool_local),
        geometry,
    )
    travel = lim[:, 1] - lim[:, 0]
    # A joint whose whole travel is under 180° (B-3 then warns) needs all of it.
    need = np.where(
        pris,
        0.5 * travel,
        np.minimum(min(MIN_SWEEP_DEG, max_sweep_deg) + 2 * SWEEP_END_MARGIN_DEG, travel - step),
    )
    grids = [np.arange(lim[i, 0], lim[i, 1] + 1e-9, step[i]) for i in range(n)]

    def targets(i: int, k: slice) -> Iterator[np.ndarray]:
        """Sensor-frame positions (rows, K, grid, 3) of joint i's targets k, for successive
        blocks of candidates: every frame of the chain along a long joint travel for all
        candidates at once took gigabytes (12 joints of +-1000 cm: 6.4 GB)."""
        # The largest arrays per candidate row: the chain's n + 1 frames (16 doubles each),
        # and the K targets' positions with their distances to 3 microphones (12 doubles).
        per_row = len(grids[i]) * max((n + 1) * 16, options.shape[1] * 12) * 8
        rows = max(1, _SEARCH_BYTES // per_row)
        for a in range(0, candidates, rows):
            q = np.repeat(cand[a : a + rows, None, :], len(grids[i]), axis=1)
            q[:, :, i] = grids[i]
            F = target_frames(chain, sensor_from_base, joints_to_internal(q, pris), i + 1)
            yield points_in_frames(F[:, None], options[i, k][None, :, None, :])

    def visible_sweeps(k: slice) -> np.ndarray:
        """Longest visible sweep (candidates, n, K) of targets k, deg / cm."""
        return np.stack(
            [
                np.concatenate(
                    [_longest_runs(visible(p, geometry))[1] * step[i] for p in targets(i, k)]
                )
                for i in range(n)
            ],
            axis=1,
        )

    # The first target of every joint if any q^s allows it; else, joint by joint, the
    # first target (in order of preference) that sweeps enough.
    arcs = visible_sweeps(slice(0, 1))
    good = arcs >= need[None, :, None]
    if not np.any(tool_ok & np.all(good.any(axis=-1), axis=1)) and options.shape[1] > 1:
        arcs = np.concatenate([arcs, visible_sweeps(slice(1, None))], axis=-1)
        good = arcs >= need[None, :, None]
    choice = np.argmax(good, axis=-1)  # (candidates, n)
    arc = np.take_along_axis(arcs, choice[..., None], axis=-1)[..., 0]
    feasible = tool_ok & np.all(good.any(axis=-1), axis=1)
    if not feasible.any():
        lost = [_why_lost(targets(i, slice(None)), geometry) for i in range(n)]
        raise _no_placement(robot, arcs, need, tool_ok, lost)
    capped = np.minimum(arc, np.where(pris, np.inf, max_sweep_deg))
    score = np.where(feasible, np.sum(capped / travel, axis=1), -np.inf)
    best = int(np.argmax(score))
    qs = cand[best]
    locals_ = options[np.arange(n), choice[best]]  # (n, 3)
    sweeps = []
    for i in range(n):
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
        start, length = (int(v) for v in _longest_runs(ok))
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


def _no_placement(
    robot: RobotDescription,
    arcs: np.ndarray,
    need: np.ndarray,
    tool_ok: np.ndarray,
    lost: list[str],
) -> ArmsigError:
    """The error of :func:`plan_measurements` when no signature configuration works."""
    reach = arcs.max(axis=(0, 2))  # best visible sweep of each joint, any q^s and target
    short = reach < need
    if not short.any():
        what = (
            "the tool probe is never visible"
            if not tool_ok.any()
            else "no single signature configuration suits every joint at once"
        )
        return ArmsigError(
            f"{robot.name}: no signature configuration keeps every target visible: {what}",
            expected=f"every target visible over its sweep ({', '.join(f'{v:g}' for v in need)})",
            fix="widen the joint limits in the description, or put the digitizer elsewhere "
            "(plan_measurements' sensor_from_base)",
        )
    k = int(np.argmax(need - reach))  # the joint that misses by most
    j = robot.joints[k]
    return ArmsigError(
        f"{robot.name}: joint {k + 1} ({j.name}) has no visible sweep: its targets are "
        f"{lost[k]} over most of its travel",
        expected=f"a visible sweep of at least {need[k]:g} {j.unit}, with target radii of "
        f"{', '.join(f'{r:g}' for r in RADIUS_FALLBACKS_CM)} cm",
        got=f"at most {reach[k]:g} {j.unit}",
        fix=f"check joint {k + 1}'s limits and the link lengths in the description (cm); the "
        "digitizer covers 30-250 cm from its microphones in front of the wall, placed as in "
        "(F.3) for the robot's first d (pass sensor_from_base to plan_measurements to move it)",
    )
