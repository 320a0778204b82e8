"""Stage ``features``: plane, centre or line of every joint (Section 4.3.2) and their accuracy.

Reads the sensor-neutral ``positions`` table. Every target of a sweep is fitted on its
own; the well-conditioned ones make the joint's feature (:mod:`pipeline.features.targets`),
and the table says which were used and why others were not. A sweep of one target
(every sonic session) gives exactly that target's fit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from pipeline.errors import ArmsigError, StageError
from pipeline.schemas import arrow_schema
from pipeline.stages.base import Stage, check_param
from pipeline.stages.frames import readings_at
from pipeline.stages.positions import positions, recorded_sigma_cm, sweep_rows, sweep_targets
from pipeline.stages.session import session_plan, session_robot

if TYPE_CHECKING:
    from pipeline.features.targets import TargetFit

PLANE_METHODS = ("lsq", "eigen")
LIST_COLUMNS = ("warnings", "targets_used", "targets_not_used")
#: Columns of :meth:`pipeline.features.expected.ExpectedAccuracy.columns` (two not float).
EXPECTED_COLUMNS = (
    "residual_dof",
    "noise_gain",
    "expected_axis_deg",
    "expected_center_cm",
    "expected_basis",
)
NOT_FLOAT = ("residual_dof", "expected_basis")


@dataclass(frozen=True)
class Params:
    """``plane_method``: which plane fit defines the joint axis (both are reported)."""

    plane_method: str = "lsq"

    def __post_init__(self) -> None:
        rule = " or ".join(PLANE_METHODS)
        check_param(self, "features", "plane_method", self.plane_method in PLANE_METHODS, rule)


def sweep_points(
    pos: pa.Table,
    joints: pa.Table,
    joint: int,
    n: int,
    prismatic: np.ndarray,
    target: str | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Usable target positions (N, 3) of sweep ``joint`` (of one ``target`` when given)
    by increasing reading, the readings (N,) and the configuration steps (N,).

    Each position is paired with the joint state of its own (sweep, step) key.
    """
    sel = sweep_rows(pos, joint, target)
    p = positions(sel)
    steps = sel.column("step").to_numpy().astype(np.int64)
    try:
        q = readings_at(joints, joint, steps, n, prismatic)[:, joint - 1]
    except StageError as exc:
        raise StageError(f"sweep {joint}: {exc}") from exc
    ok = ~np.isnan(p).any(axis=1)
    order = np.argsort(q[ok], kind="stable")
    return p[ok][order], q[ok][order], steps[ok][order]


def _nan(v: Any) -> float | None:
    return None if v is None or not np.isfinite(v) else float(v)


def _fit_row(p: np.ndarray, prismatic: bool, plane_method: str) -> dict[str, Any]:
    """The feature of one target's positions ``p`` (N, 3), by increasing reading."""
    from pipeline.features.accuracy import revolute_accuracy
    from pipeline.features.circle import fit_circle
    from pipeline.features.expected import prismatic_expected, revolute_expected
    from pipeline.features.line import fit_line
    from pipeline.features.plane import fit_plane_eigen, fit_plane_lsq, frame_about, orient_normal

    if prismatic:
        line = fit_line(p)
        expected = prismatic_expected(p, line)
        x_dir = frame_about(line.direction)[:, 0]
        row: dict[str, Any] = dict(
            plane_method="line",
            axis=line.direction,
            eigen=None,
            lsq=None,
            angle=None,
            center=line.point,
            radius=None,
            first=line.point + x_dir,
            sweep_deg=None,
            travel_cm=float(np.ptp(line.travel)),
            sigma_normal_cm=float(np.std(line.residuals, ddof=1)),
            sigma_radial_cm=None,
            sigma_e_deg=None,
            sigma_f_deg=None,
            sigma_delta_deg=None,
            sigma_delta_empirical_deg=None,
            sigma_c_cm=None,
            warnings=list(line.warnings),
        )
    else:
        eig = fit_plane_eigen(p)
        lsq = fit_plane_lsq(p)
        n_eig = orient_normal(eig.normal, p)
        n_lsq = orient_normal(lsq.normal, p)
        plane = lsq if plane_method == "lsq" else eig
        axis = n_lsq if plane_method == "lsq" else n_eig
        circle = fit_circle(p, plane)
        acc = revolute_accuracy(p, plane, circle)
        thesis = (float(acc.sigma_delta_empirical), float(acc.sigma_c))
        expected = revolute_expected(p, plane, circle, thesis)
        angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(n_eig, n_lsq)), n_eig @ n_lsq))
        row = dict(
            plane_method=plane_method,
            axis=axis,
            eigen=n_eig,
            lsq=n_lsq,
            angle=float(angle),
            center=circle.center,
            radius=float(circle.radius),
            first=p[0],
            sweep_deg=float(np.degrees(circle.sweep)),
            travel_cm=None,
            sigma_normal_cm=float(np.sqrt(acc.normal_variance)),
            sigma_radial_cm=float(np.sqrt(acc.radial_variance)),
            sigma_e_deg=float(np.degrees(acc.sigma_E)),
            sigma_f_deg=float(np.degrees(acc.sigma_F)),
            sigma_delta_deg=float(np.degrees(acc.sigma_delta)),
            # (6.12)/(6.13) were fitted for sweeps of at least 180° (B-3): no value below.
            sigma_delta_empirical_deg=_nan(np.degrees(acc.sigma_delta_empirical))
            if circle.sweep >= np.pi
            else None,
            sigma_c_cm=_nan(acc.sigma_c) if circle.sweep >= np.pi else None,
            warnings=list(dict.fromkeys([*plane.warnings, *circle.warnings])),
        )
    row.update(expected.columns(), warnings=[*row["warnings"], *expected.warnings])
    return row


def _fit_target(
    pos: pa.Table,
    joints: pa.Table,
    i: int,
    target: str,
    robot: Any,
    plane_method: str,
    floor_cm: float,
) -> TargetFit | str:
    """One target's fit in sweep ``i``, or why it cannot be fitted."""
    from pipeline.features.targets import TargetFit, why_not_usable

    n, pris = robot.n_joints, robot.prismatic
    p, _, _ = sweep_points(pos, joints, i, n, pris, target)
    if len(p) < 3:
        return f"{len(p)} usable positions (needs at least 3)"
    sigma = recorded_sigma_cm(sweep_rows(pos, i, target))
    spread = float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)))
    why = why_not_usable(spread, sigma or 0.0, bool(pris[i - 1]), floor_cm)
    if why:
        return why
    try:
        row = _fit_row(p, bool(pris[i - 1]), plane_method)
    except (ArmsigError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return f"its fit fails: {exc}"
    if sigma is None:  # no recorded noise (sonic): the fit's own residual scatter
        rad = row["sigma_radial_cm"] or 0.0  # null: unknown (3 points), taken as 0
        sigma = float(np.sqrt(((row["sigma_normal_cm"] or 0.0) ** 2 + rad**2) / 2.0))
    return TargetFit(target, len(p), sigma, row)


def _sweep_feature(
    pos: pa.Table, joints: pa.Table, i: int, robot: Any, plane_method: str
) -> dict[str, Any]:
    """Joint ``i``'s features row from the usable targets of its sweep."""
    from pipeline.features.targets import MIN_RADIUS_CM, RADIUS_SIGMAS, combine, why_ill_conditioned

    pris = bool(robot.prismatic[i - 1])
    targets = sweep_targets(pos, i)

    def usable(floor: float) -> tuple[list[TargetFit], list[str]]:
        fits: list[TargetFit] = []
        rejected: list[str] = []
        for t in targets:
            fit = _fit_target(pos, joints, i, t, robot, plane_method, floor)
            why = fit if isinstance(fit, str) else why_ill_conditioned(fit, pris, floor)
            if why is None and not isinstance(fit, str):
                fits.append(fit)
            else:
                rejected.append(f"{t}: {why}")
        return fits, rejected

    # The floor picks among a nest's targets; an only target's noise decides alone, and so
    # does every target's when none reaches the floor (a small arm's reflectors on the
    # tool, e.g. SScanSS-2's two-link example at radii of 1-2 mm with two targets).
    fits, rejected = usable(MIN_RADIUS_CM if len(targets) > 1 else 0.0)
    if not fits and len(targets) > 1:
        fits, rejected = usable(0.0)
    if not fits:
        if len(targets) <= 1:  # the message of a single target's sweep
            p, _, _ = sweep_points(pos, joints, i, robot.n_joints, robot.prismatic)
            if len(p) < 3:
                raise StageError(
                    f"sweep {i}: {len(p)} usable target positions",
                    expected="at least 3 (the thesis used 5 to 100)",
                    fix=f"re-record sweep {i} with more positions, or check its positions in "
                    "stages/positions.arrow",
                )
        raise StageError(
            f"sweep {i}: no usable target ({'; '.join(rejected) or 'none recorded'})",
            expected=f"a target that moves well above its noise: radius (travel) > "
            f"{MIN_RADIUS_CM:g} cm and > {RADIUS_SIGMAS:g} σ, with at least 3 positions",
            fix=f"re-record sweep {i} with a target away from joint {i}'s axis",
        )
    fits.sort(key=lambda f: -f.weight(pris))  # best-conditioned first: X points at it
    row = combine(fits, pris)
    row.update(
        joint=i,
        type=robot.joints[i - 1].type,
        n_points=fits[0].n_points,
        targets_used=[f.target for f in fits],
        targets_not_used=rejected,
    )
    return row


def swept_joints(session: pa.Table, n: int) -> list[int]:
    """The joints with a feature: every joint 1..n of a sweep session (a missing sweep is
    refused by :func:`_sweep_feature`); the planned sweeps of a session with a pose set,
    which identifies the chain from its poses (none, some or all joints swept too)."""
    plan = session_plan(session)
    if "poses" not in plan:
        return list(range(1, n + 1))
    return sorted(int(s["joint"]) for s in plan["sweeps"])


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.features.expected import SIGMA_COLUMNS

    if params.plane_method not in PLANE_METHODS:
        raise StageError(
            f"unknown plane_method {params.plane_method!r}", expected=" or ".join(PLANE_METHODS)
        )
    robot = session_robot(inputs["session"])
    pos, joints = inputs["positions"], inputs["joints"]
    rows = [
        _sweep_feature(pos, joints, i, robot, params.plane_method)
        for i in swept_joints(inputs["session"], robot.n_joints)
    ]
    if not rows:  # a pose set alone: no joint of its own sweep
        return arrow_schema("features").empty_table()
    out: dict[str, list[Any]] = {}

    def put(name: str, value: Any) -> None:
        out.setdefault(name, []).append(value)

    for r in rows:
        put("joint", r["joint"])
        put("type", r["type"])
        put("n_points", r["n_points"])
        put("plane_method", r["plane_method"])
        for pre, key in (("axis", "axis"), ("eigen_axis", "eigen"), ("lsq_axis", "lsq")):
            for k, c in enumerate("xyz"):
                put(f"{pre}_{c}", None if r[key] is None else float(r[key][k]))
        put("methods_angle_deg", r["angle"])
        for pre, key in (("center", "center"), ("first", "first")):
            for k, c in enumerate("xyz"):
                put(f"{pre}_{c}_cm", float(r[key][k]))
        put("radius_cm", r["radius"])
        for name in ("sweep_deg", "travel_cm", *SIGMA_COLUMNS):
            put(name, r[name])
        for name in EXPECTED_COLUMNS:
            put(name, r[name])
        put("warnings", [str(w) for w in r["warnings"]])
        put("targets_used", r["targets_used"])
        put("targets_not_used", r["targets_not_used"])
    order = arrow_schema("features").names
    return pa.table(
        {
            k: pa.array(out[k], type=pa.float64())
            if k not in ("joint", "type", "n_points", "plane_method", *LIST_COLUMNS, *NOT_FLOAT)
            else pa.array(out[k], type=pa.list_(pa.string()))
            if k in LIST_COLUMNS
            else out[k]
            for k in order
        }
    )


STAGE = Stage(
    "features",
    6,  # 5: expected accuracy per sweep, sparse / short sweep warnings; 6: a nest whose
    # targets are all below the 1 cm floor judged by their noise alone (issue 29)
    ("positions", "joints", "session"),
    Params(),
    compute,
    "plane, centre and line of every joint, with accuracy",
)
