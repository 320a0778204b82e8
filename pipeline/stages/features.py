"""Stage ``features``: plane, centre or line of every joint (Section 4.3.2) and their accuracy."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from pipeline.errors import StageError
from pipeline.features.accuracy import revolute_accuracy
from pipeline.features.circle import fit_circle
from pipeline.features.expected import prismatic_expected, require_spread, revolute_expected
from pipeline.features.line import fit_line
from pipeline.features.plane import fit_plane_eigen, fit_plane_lsq, frame_about, orient_normal
from pipeline.schemas import arrow_schema
from pipeline.stages.base import Stage, check_param
from pipeline.stages.frames import readings_at
from pipeline.stages.session import session_robot
from pipeline.stages.triangulate import positions

PLANE_METHODS = ("lsq", "eigen")
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
    tri: pa.Table, joints: pa.Table, joint: int, n: int, prismatic: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Usable target positions (N, 3) of sweep ``joint`` by increasing reading, the
    readings (N,) and the configuration steps (N,).

    Each position is paired with the joint state of its own (sweep, step) key.
    """
    sel = tri.filter(pc.equal(tri.column("sweep"), joint))
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


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    if params.plane_method not in PLANE_METHODS:
        raise StageError(
            f"unknown plane_method {params.plane_method!r}", expected=" or ".join(PLANE_METHODS)
        )
    robot = session_robot(inputs["session"])
    n, pris = robot.n_joints, robot.prismatic
    rows = []
    for i in range(1, n + 1):
        p, _, _ = sweep_points(inputs["triangulate"], inputs["joints"], i, n, pris)
        if len(p) < 3:
            raise StageError(
                f"sweep {i}: {len(p)} usable target positions",
                expected="at least 3 (the thesis used 5 to 100)",
                fix=f"re-record sweep {i} with more positions, or check its echoes in "
                "stages/compensate.arrow",
            )
        require_spread(p, i, bool(pris[i - 1]))
        row: dict[str, Any] = {"joint": i, "type": robot.joints[i - 1].type, "n_points": len(p)}
        if pris[i - 1]:
            line = fit_line(p)
            expected = prismatic_expected(p, line)
            x_dir = frame_about(line.direction)[:, 0]
            row.update(
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
            plane = lsq if params.plane_method == "lsq" else eig
            axis = n_lsq if params.plane_method == "lsq" else n_eig
            circle = fit_circle(p, plane)
            acc = revolute_accuracy(p, plane, circle)
            thesis = (float(acc.sigma_delta_empirical), float(acc.sigma_c))
            expected = revolute_expected(p, plane, circle, thesis)
            angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(n_eig, n_lsq)), n_eig @ n_lsq))
            row.update(
                plane_method=params.plane_method,
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
        rows.append(row)
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
        for name in (
            "sweep_deg",
            "travel_cm",
            "sigma_normal_cm",
            "sigma_radial_cm",
            "sigma_e_deg",
            "sigma_f_deg",
            "sigma_delta_deg",
            "sigma_delta_empirical_deg",
            "sigma_c_cm",
        ):
            put(name, r[name])
        for name in EXPECTED_COLUMNS:
            put(name, r[name])
        put("warnings", [str(w) for w in r["warnings"]])
    order = arrow_schema("features").names
    return pa.table(
        {
            k: pa.array(out[k], type=pa.float64())
            if k not in ("joint", "type", "n_points", "plane_method", "warnings", *NOT_FLOAT)
            else pa.array(out[k], type=pa.list_(pa.string()))
            if k == "warnings"
            else out[k]
            for k in order
        }
    )


STAGE = Stage(
    "features",
    4,  # 4: expected accuracy per sweep, sparse / short sweep warnings
    ("triangulate", "joints", "session"),
    Params(),
    compute,
    "plane, centre and line of every joint, with accuracy",
)
