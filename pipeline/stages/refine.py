"""Stage ``refine``: one fit of the whole kinematic chain to every measurement (issue 15).

Started from the thesis's S-Model frames (stage ``frames``), the joint axis lines and the
target points (:mod:`pipeline.refine.kinematics`, its gauge in docs/refine.md) are fitted
to the session's measurement block by :func:`pipeline.refine.solve.solve`:

- level ``points``: the usable fit positions of the ``positions`` table, three whitened
  residuals each (:mod:`pipeline.refine.points`); the check sweep stays held out;
- level ``ranges`` (sonic, ``--param refine.level=ranges``): every raw slant range, the
  sensor's own parameters (microphones, biases, speed of sound) in the fit
  (:mod:`pipeline.sensor.range_model`). A point-sensor session asked for it is refused
  with one line; its stage list runs this stage from :mod:`pipeline.stages.refine_points`,
  without the ``ranges`` input.

One row per parameter: group (``axis``, ``point``; the sensor's ``mic``, ``bias``,
``speed``), name, unit (boundary units: deg, cm), start, value, sigma and its row of the
covariance (same order as the rows). The solver's summary is in the schema metadata
(key ``armsig.refine``, :data:`META_KEY`). Disabled (``--param refine.enabled=false``):
zero rows and ``enabled: false``; stage ``chain`` then copies the thesis's frames.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.optim.lm import LOSSES
from pipeline.stages.base import Stage, check_param
from pipeline.stages.session import session_plan, session_sensor

META_KEY = b"armsig.refine"
LEVELS = ("auto", "points", "ranges")


@dataclass(frozen=True)
class Params:
    """``level``: auto (points: see :func:`resolved_level`), points, ranges (sonic);
    ``loss``/``f_scale``: the robust loss and its scale in σ of the whitened residuals
    (3: a residual beyond 3σ starts to be down-weighted); ``speed_knot_s``: knot spacing
    of the speed-of-sound spline (level ranges), 0: chosen from the rods (120 s, halved
    down to 15 s while the rods' speed ratios ask for it,
    :meth:`pipeline.sensor.speed_spline.TimeSpline.chosen`). Every parameter is recorded
    in the table's summary (:func:`refine_summary`); later stages rebuild the problem
    from it (:func:`problem_params`)."""

    enabled: bool = True
    level: str = "auto"
    loss: str = "soft_l1"
    f_scale: float = 3.0
    speed_knot_s: float = 0.0

    def __post_init__(self) -> None:
        check_param(self, "refine", "level", self.level in LEVELS, " or ".join(LEVELS))
        check_param(self, "refine", "loss", self.loss in LOSSES, " or ".join(LOSSES))
        ok = bool(np.isfinite(self.f_scale) and self.f_scale > 0)
        check_param(self, "refine", "f_scale", ok, "> 0 and finite")
        ok = bool(np.isfinite(self.speed_knot_s) and self.speed_knot_s >= 0)
        check_param(self, "refine", "speed_knot_s", ok, ">= 0 (0: chosen from the rods), finite")


def refine_summary(table: pa.Table) -> dict[str, Any]:
    """The solver's summary recorded with a ``refine`` table (``{}`` when absent)."""
    raw = (table.schema.metadata or {}).get(META_KEY)
    return json.loads(raw) if raw else {}


def problem_params(summary: Mapping[str, Any]) -> dict[str, Any]:
    """The arguments of :func:`pipeline.stages.refine_problem.session_problem` a
    ``refine`` table was fitted with (its :func:`refine_summary`): later stages rebuild
    the same problem from them, whatever ``refine.*`` parameters the run set."""
    return {k: summary[k] for k in ("loss", "f_scale", "level", "speed_knot_s")}


def internal_factors(refine: pa.Table) -> np.ndarray:
    """Per row of a ``refine`` table, the factor from its boundary unit to the internal
    one (deg -> rad; cm and ratios unchanged): values scale by it, covariances by its
    outer product."""
    unit = np.array(refine.column("unit").to_pylist())
    return np.where(unit == "deg", np.radians(1.0), 1.0)


def refined_x(refine: pa.Table) -> np.ndarray:
    """The fitted ``x`` (internal units) of a ``refine`` table."""
    return np.asarray(refine.column("value").to_numpy() * internal_factors(refine), float)


def resolved_level(params: Params, sensor: str) -> str:
    """The measurement level a session is refined at: ``auto`` is ``ranges`` for sonic
    sessions (every raw range, the sensor calibrated in the fit), ``points`` for point
    sensors. The range model's speed of sound is a function of the cycles' measurement
    times (their values), so a recording whose times run back behind the measurement order
    by more than a clock's jitter is refused with one line at that level
    (:func:`pipeline.sensor.range_rows.check_cycle_order`; issue 13: times never change a
    signature silently); log times are never read."""
    if params.level != "auto":
        return params.level
    return "ranges" if sensor == "sonic" else "points"


def _boundary(units: tuple[str, ...]) -> tuple[list[str], np.ndarray]:
    """Boundary units (rad -> deg) and the factor of each parameter."""
    out = ["deg" if u == "rad" else u for u in units]
    return out, np.array([np.degrees(1.0) if u == "rad" else 1.0 for u in units])


def _table(rows: dict[str, Any], summary: dict[str, Any]) -> pa.Table:
    table = pa.table(
        {
            "group": pa.array(rows["group"], pa.string()),
            "name": pa.array(rows["name"], pa.string()),
            "unit": pa.array(rows["unit"], pa.string()),
            "start": pa.array(rows["start"], pa.float64()),
            "value": pa.array(rows["value"], pa.float64()),
            "sigma": pa.array(rows["sigma"], pa.float64()),
            "covariance": pa.array(rows["covariance"], pa.list_(pa.float64())),
        }
    )
    return table.replace_schema_metadata({META_KEY: json.dumps(summary, sort_keys=True)})


def _disabled(level: str) -> pa.Table:
    empty: dict[str, list[Any]] = {
        k: [] for k in ("group", "name", "unit", "start", "value", "sigma", "covariance")
    }
    return _table(empty, {"enabled": False, "level": level, "status": "disabled"})


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.solve import recorded_chi2, solve
    from pipeline.stages.refine_problem import session_problem

    sensor = session_sensor(inputs["session"])
    level = resolved_level(params, sensor)
    if not params.enabled:
        return _disabled(level)
    if level == "ranges" and sensor != "sonic":
        raise StageError(
            "refine.level 'ranges' needs the raw ranges of a sonic session",
            expected="level points (or auto) for a point-sensor session",
            got=f"sensor {sensor!r}",
            fix="--param refine.level=auto",
        )
    sp = session_problem(inputs, params.loss, params.f_scale, level, params.speed_knot_s)
    spline = getattr(sp.problem.block, "spline", None)
    identifiability: dict[str, Any] = {}
    if "poses" in session_plan(inputs["session"]):
        sol, identifiability = _fit_pose_set(sp, inputs["positions"])
    else:
        sol = solve(sp.problem, sp.x0)
    chi2_recorded = recorded_chi2(sp.problem, sol)
    units, factor = _boundary(sp.units)
    cov = sol.covariance * np.outer(factor, factor)
    summary = {
        "enabled": True,
        "level": level,
        "status": sol.status,
        "message": sol.message,
        "iterations": sol.iterations,
        "n_residuals": sol.n_residuals,
        "n_params": len(sol.x),
        "chi2": sol.chi2,
        "dof": sol.dof,
        "noise_scale": sol.noise_scale,
        "chi2_recorded_sensor": chi2_recorded,
        "loss": params.loss,
        "f_scale": params.f_scale,
        "speed_knot_s": params.speed_knot_s,
        "speed_knot_spacing_s": None if spline is None else spline.spacing_s,
        "rows_down_weighted": sol.down_weighted,
    }
    if identifiability:
        summary["identifiability"] = identifiability
    rows = {
        "group": list(sp.groups),
        "name": list(sp.names),
        "unit": units,
        "start": sp.x0 * factor,
        "value": sol.x * factor,
        "sigma": sol.sigma * factor,
        "covariance": [row for row in cov],
    }
    return _table(rows, summary)


def _fit_pose_set(sp: Any, positions: pa.Table) -> tuple[Any, dict[str, Any]]:
    """The fit of a session with a pose set, the parameters its data cannot identify held
    at the start (:func:`pipeline.refine.identifiability.fit_identifiable`), and the
    analysis as the summary records it."""
    from pipeline.refine.identifiability import fit_identifiable, summary
    from pipeline.stages.positions import recorded_sigma_cm
    from pipeline.sweeps import POSES_SWEEP

    keys = sp.problem.block.keys
    sweep = keys.column("sweep").to_numpy()
    n_poses = len(set(keys.column("step").to_numpy()[sweep == POSES_SWEEP].tolist()))
    stated = recorded_sigma_cm(positions) is not None
    sol, ident = fit_identifiable(sp.problem, sp.x0, sp.units, stated, keys.num_rows)
    return sol, summary(ident, sp.names, n_poses, keys.num_rows)


def held_parameters(refine: pa.Table) -> np.ndarray:
    """Per row of a ``refine`` table, whether the fit held it at its start (not
    identifiable: the summary's ``identifiability.held``)."""
    held = {h["name"] for h in refine_summary(refine).get("identifiability", {}).get("held", [])}
    return np.array([n in held for n in refine.column("name").to_pylist()], bool)


STAGE = Stage(
    "refine",
    4,  # 3: the rods' speed spline fit on its normal equations (linear in the samples);
    # 4: the speed spline's knots chosen from the rods, every parameter in the summary,
    # single-cycle sonic positions weighed by the range noise law (level points)
    ("session", "joints", "positions", "frames", "ranges"),
    Params(),
    compute,
    "joint refinement of the chain (axis lines, target points) from all measurements",
)
