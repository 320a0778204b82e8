"""Sweep plans (issue 28): points per sweep and sweep range per joint, before measuring.

The layout is the simulated rig's (:func:`pipeline.rig.plan.plan_measurements`: the
signature configuration, each link's target and its nominal radius ``R_i``, each joint's
widest visible sweep up to 300°): (6.12) and (6.13) say a longer sweep only helps, so the
range per joint is the longest the limits and the sensor allow. The points per sweep
``N_i`` then follow from the sensor's noise along the plane normal (``σ_n``) and the radius
(``σ_r``) at the sweep's points (the sonic digitizer's trilateration of the mean of
``N_avg`` cycles, or the tracker's law, or ``--sigma-mm``):

* for a wanted feature accuracy, ``σ_δ`` of the planes and/or ``σ_c`` of the centers, the
  fewest points that meet it by (6.11)-(6.13) where the thesis states them, and by the
  exact statistics of the arc where it is silent (sweeps under 180°):
  :func:`pipeline.features.accuracy.points_for_accuracy`;
* for a wanted tool accuracy (``target_rms_cm``), on which the thesis is silent, from the
  covariance of the whole fit: the design model observing every planned point (the
  refinement's information, :mod:`pipeline.refine.plan`), its predicted RMS tool error
  over the workspace after the audit's alignment (:func:`sweep_covariance`: the readings
  of the joints a sweep holds err by one constant for the whole sweep, which more points
  do not average); every ``N_i`` is scaled by one factor
  (information grows as ``N``) to the first whose audited RMS stays under the target with
  95 % probability, as pose plans do.

The file a robot program reads: :func:`pipeline.rig.pose_file.write_sweep_plan`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, positive_in_range
from pipeline.features.accuracy import MAX_POINTS, MIN_POINTS, points_for_accuracy, sweep_accuracy
from pipeline.robots.description import RobotDescription
from pipeline.sweeps import TOOL_SWEEP

#: Points per sweep when nothing else asks: the thesis's N_i (Sections 6.4, 7.4.4) and
#: ``simulate``'s default.
DEFAULT_POINTS = 100
#: Slant ranges the thesis's digitizer needs per position and cycle ((6.7): 7).
THESIS_RANGES_PER_CYCLE = 7


@dataclass(frozen=True)
class SweepSpec:
    """One joint's sweep: its range (boundary units), its target's nominal radius (cm),
    the planned points, the sensor's normal and radial σ there (cm), and the predicted
    ``σ_δ`` (deg) and ``σ_c`` (cm) with the law used (``(6.11)``, ``(6.12)`` with
    ``(6.13)``, or ``arc``; ``line`` for a prismatic joint, which has no circle)."""

    joint: int
    name: str
    first: float
    last: float
    radius_cm: float
    points: int
    sigma_n_cm: float
    sigma_r_cm: float
    plane_sigma_deg: float
    center_sigma_cm: float
    law: str


@dataclass(frozen=True)
class SweepPlan:
    """The sweeps (in measuring order, target n first: Figure 6-7), the signature
    configuration, the cycles averaged per position, the tool probe, and the whole fit's
    prediction over the workspace (cm): RMS, its 95 % quantile over robots, the 95 % of
    the workspace, and the parameters the plan cannot identify."""

    sensor: str
    signature_q: tuple[float, ...]
    n_avg: int
    sweeps: tuple[SweepSpec, ...]
    tool_local_cm: tuple[float, float, float]
    rms_cm: float
    rms_q95_cm: float
    p95_cm: float
    unidentified: tuple[str, ...]

    @property
    def positions(self) -> int:
        """Positions measured: every sweep's points and the tool probe once."""
        return sum(s.points for s in self.sweeps) + 1

    def to_dict(self) -> dict[str, Any]:
        return {
            "sensor": self.sensor,
            "signature_q": list(self.signature_q),
            "n_avg": self.n_avg,
            "positions": self.positions,
            "sweeps": [asdict(s) for s in self.sweeps],
            "tool_local_cm": list(self.tool_local_cm),
            "predicted_rms_cm": self.rms_cm,
            "predicted_rms_q95_cm": self.rms_q95_cm,
            "predicted_p95_cm": self.p95_cm,
            "unidentified": list(self.unidentified),
        }

    def readings(self) -> list[tuple[str, np.ndarray]]:
        """Each sweep's joint values (N_i, n, boundary units) in measuring order, then the
        tool probe's at q^s: what the robot program runs."""
        qs = np.array(self.signature_q)
        out = []
        for s in self.sweeps:
            q = np.tile(qs, (s.points, 1))
            q[:, s.joint - 1] = np.round(np.linspace(s.first, s.last, s.points), 6)
            out.append((str(s.joint), q))
        return [*out, ("tool", qs[None, :])]


def measurement_count(points: tuple[int, ...], n_avg: int, ranges_per_cycle: int) -> int:
    """Raw slant ranges of a sweep session, (6.7): ``Σ_i ranges · N_avg · N_i``."""
    return ranges_per_cycle * n_avg * sum(points)  # Eq. (6.7)


def _check(plane_sigma_deg: float | None, center_sigma_cm: float | None, **sizes: Any) -> None:
    for name, v in (("plane_sigma_deg", plane_sigma_deg), ("center_sigma_cm", center_sigma_cm),
                    *sizes.items()):  # fmt: skip
        positive_in_range(f"sweep plan: {name}", v, fix="--sweeps --plane-sigma-deg 0.005 "
                          "--center-sigma-mm 0.02, or --target-rms-mm 0.1")  # fmt: skip


def plan_sweeps(
    robot: RobotDescription,
    sensor: str = "sonic",
    plane_sigma_deg: float | None = None,
    center_sigma_cm: float | None = None,
    target_rms_cm: float | None = None,
    sigma_cm: float | None = None,
    points: int | None = None,
    n_avg: int = 10,
    max_sweep_deg: float = 300.0,
) -> SweepPlan:
    """The sweep plan of ``robot`` (module docstring). ``points`` fixes every ``N_i``
    (the feature targets are then only reported); otherwise the feature targets set them
    (:data:`~pipeline.features.accuracy.MIN_POINTS` without one, or
    :data:`DEFAULT_POINTS` when no target at all is given) and ``target_rms_cm`` scales
    them up. ``sigma_cm``: the point noise per coordinate instead of the sensor's law;
    ``n_avg``: cycles averaged per position (sonic; a tracker measures once)."""
    from pipeline.rig.options import SENSORS
    from pipeline.rig.plan import default_sensor_from_base
    from pipeline.rig.simulate import session_plan
    from pipeline.sensor.geometry import default_geometry

    if sensor not in SENSORS:
        raise ArmsigError(f"unknown sensor {sensor!r}", expected=", ".join(SENSORS))
    if sensor == "camera":  # issue 39: which poses calibrate a camera best is not planned yet
        raise ArmsigError(
            "pipeline plan --sweeps plans joint sweeps of the sonic digitizer or a tracker",
            expected="--sensor sonic or tracker",
            got="--sensor camera",
            fix="simulate camera images at random poses (`pipeline simulate NAME --sensor "
            "camera --poses 40`)",
        )
    _check(plane_sigma_deg, center_sigma_cm, target_rms_cm=target_rms_cm, sigma_cm=sigma_cm)
    if points is not None and not MIN_POINTS <= points <= MAX_POINTS:
        raise ArmsigError("sweep plan: points per sweep out of range",
                          expected=f"{MIN_POINTS} to {MAX_POINTS}", got=str(points))  # fmt: skip
    if not 1 <= n_avg <= 100:
        raise ArmsigError("sweep plan: cycles per position out of range", expected="1 to 100",
                          got=str(n_avg))  # fmt: skip
    n_avg = n_avg if sensor == "sonic" else 1
    geometry = default_geometry()
    placement = default_sensor_from_base(robot)
    layout = session_plan(robot, geometry, placement, MIN_POINTS, n_avg, max_sweep_deg)
    wanted = plane_sigma_deg is not None or center_sigma_cm is not None
    base = points or (DEFAULT_POINTS if not wanted and target_rms_cm is None else MIN_POINTS)
    plane = None if plane_sigma_deg is None else np.radians(plane_sigma_deg)
    specs = []
    for s in layout.sweeps:
        spec = _sweep_spec(robot, sensor, layout, s, placement, geometry, n_avg, sigma_cm, base)
        if points is None and wanted and spec.law != "line":
            x = np.radians(spec.last - spec.first)
            args = (spec.sigma_n_cm, spec.sigma_r_cm, spec.radius_cm, x)
            spec = _with_points(spec, points_for_accuracy(*args, plane, center_sigma_cm))
        specs.append(spec)
    plan = _whole_fit(robot, sensor, layout, placement, geometry, n_avg, sigma_cm, specs)
    if target_rms_cm is not None and points is None:
        plan = _scaled_to(plan, target_rms_cm, lambda sp: _whole_fit(
            robot, sensor, layout, placement, geometry, n_avg, sigma_cm, sp))  # fmt: skip
    return plan


def _with_points(spec: SweepSpec, n: int) -> SweepSpec:
    """``spec`` with ``n`` points (capped at MAX_POINTS) and its accuracy there."""
    from dataclasses import replace

    n = min(n, MAX_POINTS)
    if spec.law == "line":
        return replace(spec, points=n)
    x = np.radians(spec.last - spec.first)
    d, c, law = sweep_accuracy(spec.sigma_n_cm, spec.sigma_r_cm, spec.radius_cm, n, x)
    return replace(spec, points=n, plane_sigma_deg=float(np.degrees(d)), center_sigma_cm=c,
                   law=law)  # fmt: skip


def _point_cov(
    p: np.ndarray, sensor: str, geometry: Any, n_avg: int, sigma_cm: float | None
) -> np.ndarray:
    """Σ (K, 3, 3) of measured positions ``p`` (K, 3): the stated σ, the tracker's law, or
    the sonic trilateration of the mean of ``n_avg`` cycles (as the refinement weighs)."""
    from pipeline.refine.points import trilateration_covariances
    from pipeline.rig import tracker

    if sigma_cm is not None:
        return np.full(len(p), sigma_cm**2)[:, None, None] * np.eye(3)
    if sensor == "tracker":
        return tracker.sigma_cm(p)[:, None, None] ** 2 * np.eye(3)
    return trilateration_covariances(p, geometry, np.full(len(p), float(n_avg)))


def _sweep_spec(
    robot: RobotDescription,
    sensor: str,
    layout: Any,
    s: Any,
    placement: np.ndarray,
    geometry: Any,
    n_avg: int,
    sigma_cm: float | None,
    n: int,
) -> SweepSpec:
    """Sweep ``s`` of the layout with ``n`` points: its range, radius and the sensor's σ
    along its plane's normal and its radius (RMS over the sweep's points)."""
    from pipeline.rig.plan import points_in_frames, target_frames
    from pipeline.units import joints_to_internal

    j, pris = s.joint, robot.prismatic
    first, last = s.q_values[0], s.q_values[-1]
    q = np.tile(np.array(layout.signature_q), (64, 1))
    q[:, j - 1] = np.linspace(first, last, 64)
    T = target_frames(robot.design_chain(), placement, joints_to_internal(q, pris), j)
    p = points_in_frames(T, np.array(s.target_local_cm))
    cov = _point_cov(p, sensor, geometry, n_avg, sigma_cm)
    a = T[:, :3, 2]  # the joint's axis (the frame's z)
    u = p - T[:, :3, 3] - np.einsum("ki,ki->k", p - T[:, :3, 3], a)[:, None] * a
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    sn = float(np.sqrt(np.mean(np.einsum("ki,kij,kj->k", a, cov, a))))
    sr = float(np.sqrt(np.mean(np.einsum("ki,kij,kj->k", u, cov, u))))
    spec = SweepSpec(j, robot.joints[j - 1].name, first, last,
                     float(np.hypot(*s.target_local_cm[:2])), n, sn, sr, np.nan, np.nan,
                     "line" if pris[j - 1] else "")  # fmt: skip
    return _with_points(spec, n)


def _whole_fit(
    robot: RobotDescription,
    sensor: str,
    layout: Any,
    placement: np.ndarray,
    geometry: Any,
    n_avg: int,
    sigma_cm: float | None,
    specs: list[SweepSpec],
) -> SweepPlan:
    """The plan of ``specs`` with the whole fit's prediction (module docstring)."""
    from pipeline.planning import WORKSPACE, design_model, prediction
    from pipeline.refine.held_joints import sweep_covariance
    from pipeline.refine.plan import workspace_information
    from pipeline.refine.uncertainty import model_error_maps, tool_model

    plan = SweepPlan(sensor, layout.signature_q, n_avg, tuple(specs), layout.tool_local_cm,
                     np.nan, np.nan, np.nan, ())  # fmt: skip
    sweep, q = zip(*plan.readings(), strict=True)
    ids = np.concatenate([np.full(len(v), TOOL_SWEEP if k == "tool" else int(k))
                          for k, v in zip(sweep, q, strict=True)])  # fmt: skip
    local = {s.joint: np.array(s.target_local_cm) for s in layout.sweeps}
    local[TOOL_SWEEP] = np.array(layout.tool_local_cm)
    model, x = design_model(robot, placement, ids, local, np.concatenate(q))
    cov = _point_cov(model.positions(x), sensor, geometry, n_avg, sigma_cm)
    J, Sigma = sweep_covariance(model, x, robot, cov, ids)
    A, B = model_error_maps(tool_model(model, robot.random_configurations(WORKSPACE, 0)), x)
    M = workspace_information(B)
    pred = prediction(J, model.param_names, model.param_units, A, B, M, Sigma)
    from dataclasses import replace

    return replace(plan, rms_cm=pred["rms_cm"], rms_q95_cm=pred["rms_q95_cm"],
                   p95_cm=pred["p95_cm"], unidentified=pred["unidentified"])  # fmt: skip


def _scaled_to(plan: SweepPlan, target_cm: float, evaluate: Any) -> SweepPlan:
    """``plan`` with every ``N_i`` scaled by the smallest factor (never below 1, to 2 %)
    whose whole fit stays under ``target_cm`` with 95 % probability, or every sweep at
    :data:`MAX_POINTS` when none does. Without the held joints' shared errors the RMS
    would fall as ``1/√N``, so ``(q95 / target)²`` is the least factor that can do; the
    rest is a bisection (the RMS falls with every point added)."""
    base = [s.points for s in plan.sweeps]

    def at(factor: float) -> SweepPlan:
        n = [int(min(np.ceil(factor * b), MAX_POINTS)) for b in base]
        return evaluate([_with_points(s, k) for s, k in zip(plan.sweeps, n, strict=True)])

    lo = max(1.0, (plan.rms_q95_cm / target_cm) ** 2)
    best = at(lo)
    if best.rms_q95_cm <= target_cm:
        return best
    hi = MAX_POINTS / min(base)
    best = at(hi)
    if best.rms_q95_cm > target_cm:
        return best  # unreachable: the most points (the caller warns)
    while hi / lo > 1.02:
        mid = np.sqrt(lo * hi)
        trial = at(mid)
        if trial.rms_q95_cm <= target_cm:
            hi, best = mid, trial
        else:
            lo = mid
    return best


def write_sweep_plan(
    path: str | Path,
    robot: RobotDescription,
    plan: SweepPlan,
    force: bool = False,
    inputs: Sequence[str | Path] = (),
) -> Path:
    """Write ``plan`` as a sweep plan file (:func:`pipeline.rig.pose_file.write_sweep_plan`);
    an existing file is refused unless ``force``, and never one of the command's
    ``inputs``."""
    from pipeline.atomic import check_new_file
    from pipeline.rig.pose_file import write_sweep_plan as write

    out = Path(path)
    check_new_file(out, "sweep plan", force, inputs)
    lines = [
        f"armsig sweep plan: {robot.name}, {plan.sensor}, {plan.positions} positions "
        f"(x {plan.n_avg} cycles); predicted RMS tool error {plan.rms_cm:.3g} cm (under "
        f"{plan.rms_q95_cm:.3g} cm with 95 % probability), 95 % {plan.p95_cm:.3g} cm",
        *(f"joint {s.joint} ({s.name}): {s.points} points over {s.first:g}..{s.last:g}, "
          f"radius {s.radius_cm:.4g} cm; plane sigma {s.plane_sigma_deg:.3g} deg, center "
          f"sigma {s.center_sigma_cm:.3g} cm {s.law}" for s in plan.sweeps),
    ]  # fmt: skip
    return write(out, robot, plan.readings(), "\n".join(lines))
