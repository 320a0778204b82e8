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
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.optim.lm import LOSSES
from pipeline.stages.base import Stage, check_param
from pipeline.stages.session import session_plan, session_robot, session_sensor

if TYPE_CHECKING:
    from pipeline.kinematics.nongeometric import NonGeometric
    from pipeline.robots.description import RobotDescription

META_KEY = b"armsig.refine"
LEVELS = ("auto", "points", "ranges")
#: ``refine.nongeometric``: which non-geometric terms the fit has (issue 27).
NONGEOMETRIC = ("auto", "none", "compliance", "harmonic", "compliance+harmonic")


@dataclass(frozen=True)
class Params:
    """``level``: auto (points: see :func:`resolved_level`), points, ranges (sonic);
    ``loss``/``f_scale``: the robust loss and its scale in σ of the whitened residuals
    (3: a residual beyond 3σ starts to be down-weighted); ``speed_knot_s``: knot spacing
    of the speed-of-sound spline (level ranges), 0: chosen from the rods (120 s, halved
    down to 15 s while the rods' speed ratios ask for it,
    :meth:`pipeline.sensor.speed_spline.TimeSpline.chosen`); ``nongeometric``: the
    non-geometric terms (:mod:`pipeline.kinematics.nongeometric`), ``auto``: joint
    compliance under gravity when the data show it above their noise
    (:func:`nongeometric_kinds`, :func:`significance`). Every parameter is recorded in the
    table's summary (:func:`refine_summary`); later stages rebuild the problem from it
    (:func:`problem_params`)."""

    enabled: bool = True
    level: str = "auto"
    loss: str = "soft_l1"
    f_scale: float = 3.0
    speed_knot_s: float = 0.0
    nongeometric: str = "auto"

    def __post_init__(self) -> None:
        check_param(self, "refine", "level", self.level in LEVELS, " or ".join(LEVELS))
        check_param(self, "refine", "loss", self.loss in LOSSES, " or ".join(LOSSES))
        ok = bool(np.isfinite(self.f_scale) and self.f_scale > 0)
        check_param(self, "refine", "f_scale", ok, "> 0 and finite")
        ok = bool(np.isfinite(self.speed_knot_s) and self.speed_knot_s >= 0)
        check_param(self, "refine", "speed_knot_s", ok, ">= 0 (0: chosen from the rods), finite")
        ok = self.nongeometric in NONGEOMETRIC
        check_param(self, "refine", "nongeometric", ok, " or ".join(NONGEOMETRIC))


def refine_summary(table: pa.Table) -> dict[str, Any]:
    """The solver's summary recorded with a ``refine`` table (``{}`` when absent)."""
    raw = (table.schema.metadata or {}).get(META_KEY)
    return json.loads(raw) if raw else {}


def problem_params(summary: Mapping[str, Any]) -> dict[str, Any]:
    """The arguments of :func:`pipeline.stages.refine_problem.session_problem` a
    ``refine`` table was fitted with (its :func:`refine_summary`): later stages rebuild
    the same problem from them, whatever ``refine.*`` parameters the run set."""
    from pipeline.kinematics.nongeometric import Terms

    out: dict[str, Any] = {k: summary[k] for k in ("loss", "f_scale", "level", "speed_knot_s")}
    out["terms"] = Terms.from_names(summary.get("nongeometric", {}).get("terms", []))
    return out


def nongeometric_kinds(setting: str) -> tuple[str, ...]:
    """The term kinds of ``refine.nongeometric``: ``auto`` is compliance, kept only when
    the data show it above their noise (:func:`significance`; a joint sweep sees the
    gravity torque of the joints it moves change too). The harmonics are never
    automatic: a joint's first harmonic identified over part of a turn extrapolates
    (issue 27: fitted on the UR10's Series C, whose first joint covers 128°, it tripled
    the error on every other series)."""
    if setting == "auto":
        return ("compliance",)
    return () if setting == "none" else tuple(setting.split("+"))


def internal_factors(refine: pa.Table) -> np.ndarray:
    """Per row of a ``refine`` table, the factor from its boundary unit to the internal
    one (deg -> rad; cm and ratios unchanged): values scale by it, covariances by its
    outer product."""
    unit = refine.column("unit").to_pylist()
    return np.array([np.radians(1.0) if u == "deg" or u.startswith("deg/") else 1.0 for u in unit])


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
    """Boundary units (rad -> deg, rad/cm -> deg/cm) and the factor of each parameter."""
    angular = [u.startswith("rad") for u in units]
    out = ["deg" + u[3:] if a else u for u, a in zip(units, angular, strict=True)]
    return out, np.array([np.degrees(1.0) if a else 1.0 for a in angular])


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
    from pipeline.refine.solve import recorded_chi2
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
    from pipeline.kinematics.nongeometric import all_terms
    from pipeline.stages.refine_problem import measured_payloads, with_terms

    robot = session_robot(inputs["session"])
    kinds = nongeometric_kinds(params.nongeometric)
    payloads = measured_payloads(inputs["joints"])
    if "compliance" in kinds and len(payloads) > 1:  # a changed payload is then predicted
        kinds += ("payload",)
    terms = all_terms(robot.prismatic, kinds)
    args = (inputs, params.loss, params.f_scale, level, params.speed_knot_s)
    left_out: dict[str, Any] | None = None
    rigid_fit: dict[str, Any] | None = None  # the rigid solution, when the terms replace it
    if params.nongeometric == "auto" and terms:
        # The rigid chain first (from the design, exactly as before issue 27); the terms
        # only when its solution shows them (never fitted to noise), from that solution.
        sp = session_problem(*args)
        sol, identifiability = fit_session(sp, inputs)
        with_them = with_terms(sp, terms, inputs)
        if not with_them.problem.model.terms:
            left_out = {"significant": False, "why": "no term the readings excite"}
        elif _too_few_for(with_them):
            left_out = {"significant": False, "why": "too few coordinates (2 per parameter)"}
        else:
            x_start = with_rigid_solution(with_them, sp, sol.x)
            left_out = significance(with_them.problem, x_start, sol, identifiability)
            if left_out["significant"]:  # the rigid fit kept: the holdout compares with it
                rigid_fit = {
                    "x": sol.x.tolist(),
                    "noise_scale": sol.noise_scale,
                    "held": [h["name"] for h in identifiability.get("held", [])],
                }
                sp = with_them
                sol, identifiability = fit_session(sp, inputs, (x_start, sol.f_scale))
    else:
        sp = session_problem(*args, terms)
        sol, identifiability = fit_session(sp, inputs)
    spline = getattr(sp.problem.block, "spline", None)
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
        "f_scale_used": sol.f_scale,
    }
    if identifiability:
        summary["identifiability"] = identifiability
    if sp.problem.model.terms or left_out:
        summary["nongeometric"] = {
            "setting": params.nongeometric,
            "terms": list(sp.problem.model.terms.names),
            "measured_payloads_kg": list(payloads),
            **({"test": left_out} if left_out else {}),
            **({"rigid_fit": rigid_fit} if rigid_fit else {}),
        }
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


#: ``refine.nongeometric=auto`` keeps the terms when the F-test of their χ² reduction has a
#: p-value below this: a rigid robot's noise passes it once in a thousand sessions.
SIGNIFICANCE = 1e-3


def significance(
    problem: Any, x_start: np.ndarray, rigid: Any, identifiability: dict[str, Any]
) -> dict[str, Any]:
    """Whether the non-geometric terms of ``problem`` would explain more than noise, judged
    at the rigid chain's solution ``rigid`` (``x_start``: that solution with the terms at
    zero; ``identifiability``: its summary, whose held parameters stay out): the score
    (Lagrange multiplier) test of the nested models, ``LM = gᵀ A⁻¹ g / s²`` with ``A``,
    ``g`` the normal equations of the problem with the terms at ``x_start`` (the rigid
    parameters' gradient is zero there, so ``g`` is the terms'), ``s²`` the rigid fit's
    χ²/dof; ``F = LM / p`` over the ``p`` terms, p-value of ``F(p, dof − p)`` below
    :data:`SIGNIFICANCE`. One linearization: a rigid robot costs no second fit. A rigid
    chain that fits to rounding (noiseless data of a rigid robot) keeps no terms."""
    # The F distribution's survival function; not scipy.stats, which imports
    # scipy.optimize and scipy.interpolate (~0.3 s of a cold run, issue 18).
    from scipy.special import fdtrc

    from pipeline.optim.lm import rho
    from pipeline.refine.solve import linearize, normal_equations

    if rigid.dof <= 0:
        return {"significant": False, "why": "no degree of freedom"}
    lin = linearize(problem, x_start)
    s2 = float(np.sum(lin.r**2)) / rigid.dof
    if s2 <= 1e-14:  # residuals ~1e-7 σ: the rigid chain is exact
        return {"significant": False, "why": "the rigid chain fits the data to rounding"}
    w = np.ones_like(lin.r)
    if problem.loss != "linear":  # the rigid fit's robust weights (its loss scale)
        w = rho(problem.loss, (lin.r / rigid.f_scale) ** 2)[1]
        s2 = float(np.sum(w * lin.r**2)) / rigid.dof
    A, g = normal_equations(problem, x_start, lin)(w)
    names = {h["name"] for h in identifiability.get("held", [])}
    held = np.array([n in names for n in problem_names(problem)], bool)
    free = ~held & (np.abs(np.diag(A)) > 0)
    b = np.zeros(len(g), bool)
    b[problem.model.beta_slice] = True
    p = int((free & b).sum())
    dof = rigid.dof - p
    if p == 0 or dof <= 0:
        return {"significant": False, "why": "no identifiable term"}
    gf = g[free]
    LM = float(gf @ np.linalg.lstsq(A[np.ix_(free, free)], gf, rcond=None)[0]) / s2
    F = LM / p
    p_value = float(fdtrc(p, dof, F))
    return {
        "significant": p_value < SIGNIFICANCE,
        "F": F,
        "p_value": p_value,
        "terms_tested": p,
        "why": f"score test of the terms at the rigid solution, p "
        f"{'<' if p_value < SIGNIFICANCE else '>='} {SIGNIFICANCE:g}",
    }


def problem_names(problem: Any) -> tuple[str, ...]:
    """The names of ``problem``'s parameters: the chain's, then the block's."""
    return (*problem.model.param_names, *problem.block.param_names)


def with_rigid_solution(sp: Any, rigid: Any, x_rigid: np.ndarray) -> np.ndarray:
    """The start of ``sp`` (a problem with non-geometric terms) with the parameters it
    shares with ``rigid`` (the same session without them) at ``x_rigid``, its solution,
    and the terms at zero: the chain's parameters come first (the terms are the last of
    them), the block's after."""
    x = np.array(sp.x0, float)
    n_rigid, n_kin = rigid.problem.n_kin, sp.problem.n_kin
    x[:n_rigid] = x_rigid[:n_rigid]
    x[n_kin:] = x_rigid[n_rigid:]
    return x


def _too_few_for(sp: Any) -> bool:
    """Whether the non-geometric terms of ``sp`` take its parameters past what its
    measured coordinates can identify (:data:`pipeline.refine.identifiability.
    COORDINATES_PER_PARAMETER` each)."""
    from pipeline.refine.identifiability import COORDINATES_PER_PARAMETER

    measured = getattr(sp.problem.block, "measured", None)
    if not sp.problem.model.terms or measured is None:
        return False
    return bool(3 * len(measured) < COORDINATES_PER_PARAMETER * sp.problem.n_params)


def fit_session(sp: Any, inputs: Mapping[str, Any], warm: Any = None) -> tuple[Any, dict[str, Any]]:
    """The solution of a session's problem ``sp`` from its start (or from ``warm``: a
    nearer start and the robust scale of the fit it came from, held parameters staying
    at the start's values), and its identifiability summary (``{}`` without a pose set:
    joint sweeps see every parameter)."""
    from pipeline.refine.solve import solve

    if "poses" in session_plan(inputs["session"]):
        return _fit_pose_set(sp, inputs["positions"], warm)
    if warm is None:
        return solve(sp.problem, sp.x0), {}
    return solve(sp.problem, warm[0], f_scale_hint=warm[1]), {}


def _fit_pose_set(sp: Any, positions: pa.Table, warm: Any = None) -> tuple[Any, dict[str, Any]]:
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
    x_warm, hint = (None, None) if warm is None else warm
    sol, ident = fit_identifiable(sp.problem, sp.x0, sp.units, stated, keys.num_rows, x_warm, hint)
    return sol, summary(ident, sp.names, n_poses, keys.num_rows)


def nongeometric_model(refine: pa.Table, robot: RobotDescription) -> NonGeometric | None:
    """The non-geometric terms a ``refine`` table fitted (rows of groups ``compliance``
    and ``harmonic``) as the map from readings to where the joints sit, on ``robot``'s
    design chain (:mod:`pipeline.kinematics.nongeometric`); None without such rows: the
    rigid signature."""
    from pipeline.kinematics.nongeometric import KINDS, NonGeometric, Terms

    groups = np.array(refine.column("group").to_pylist(), dtype=object)
    rows = np.isin(groups, KINDS)
    if not rows.any():
        return None
    names = [str(n) for n in np.array(refine.column("name").to_pylist())[rows]]
    payloads = refine_summary(refine).get("nongeometric", {}).get("measured_payloads_kg", [])
    return NonGeometric(
        Terms.from_names(names),
        refined_x(refine)[rows],
        robot.design_chain(),
        payload_kg=float(payloads[0]) if payloads else 0.0,
        measured_payloads_kg=tuple(float(m) for m in payloads),
    )


def held_parameters(refine: pa.Table) -> np.ndarray:
    """Per row of a ``refine`` table, whether the fit held it at its start (not
    identifiable: the summary's ``identifiability.held``)."""
    held = {h["name"] for h in refine_summary(refine).get("identifiability", {}).get("held", [])}
    return np.array([n in held for n in refine.column("name").to_pylist()], bool)


STAGE = Stage(
    "refine",
    6,  # 3: the rods' speed spline fit on its normal equations (linear in the samples);
    # 4: the speed spline's knots chosen from the rods, every parameter in the summary,
    # single-cycle sonic positions weighed by the range noise law (level points);
    # 5: non-geometric terms (refine.nongeometric), the robust scale follows understated
    # noise (f_scale_used); 6: a target on the last link (plan.tool_targets) is one point
    # in every joint sweep that measures it, named tool/<target> (was poses/<target>)
    ("session", "joints", "positions", "frames", "ranges"),
    Params(),
    compute,
    "joint refinement of the chain (axis lines, target points) from all measurements",
)
