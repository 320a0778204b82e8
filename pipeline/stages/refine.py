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
from dataclasses import dataclass, replace
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
    non-geometric terms (:mod:`pipeline.kinematics.nongeometric`), ``auto``: the rigid
    chain, joint compliance under gravity, joint-angle harmonics or both, chosen by
    k-fold cross-validation over blocks of the measurement order
    (:mod:`pipeline.refine.model_choice`, :func:`cross_validated`); ``cv_folds``: that
    k (5: each fold's refit keeps 80 % of every sweep). Every parameter is recorded in
    the table's summary (:func:`refine_summary`); later stages rebuild the problem from
    it (:func:`problem_params`)."""

    enabled: bool = True
    level: str = "auto"
    loss: str = "soft_l1"
    f_scale: float = 3.0
    speed_knot_s: float = 0.0
    nongeometric: str = "auto"
    cv_folds: int = 5

    def __post_init__(self) -> None:
        check_param(self, "refine", "level", self.level in LEVELS, " or ".join(LEVELS))
        check_param(self, "refine", "loss", self.loss in LOSSES, " or ".join(LOSSES))
        ok = bool(np.isfinite(self.f_scale) and self.f_scale > 0)
        check_param(self, "refine", "f_scale", ok, "> 0 and finite")
        ok = bool(np.isfinite(self.speed_knot_s) and self.speed_knot_s >= 0)
        check_param(self, "refine", "speed_knot_s", ok, ">= 0 (0: chosen from the rods), finite")
        ok = self.nongeometric in NONGEOMETRIC
        check_param(self, "refine", "nongeometric", ok, " or ".join(NONGEOMETRIC))
        check_param(self, "refine", "cv_folds", 2 <= self.cv_folds <= 20, "2 to 20")


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


def nongeometric_kinds(setting: str, payloads: tuple[float, ...] = ()) -> tuple[str, ...]:
    """The term kinds of an explicit ``refine.nongeometric`` setting or a candidate of
    ``auto`` (:data:`pipeline.refine.model_choice.CANDIDATES`; ``none`` and ``rigid``:
    none), with the payload terms beside the compliance when the session measured two
    payloads or more (``payloads``, kg): a changed payload is then predicted."""
    kinds = () if setting in ("none", "rigid") else tuple(setting.split("+"))
    if "compliance" in kinds and len(payloads) > 1:
        kinds += ("payload",)
    return kinds


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
    from pipeline.refine.solve import release_chunks

    try:
        return _compute(inputs, params)
    finally:  # the last fitted model's chunks are not kept past the stage
        release_chunks()


def _compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
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
    from pipeline.stages.refine_problem import measured_payloads

    robot = session_robot(inputs["session"])
    payloads = measured_payloads(inputs["joints"])
    args = (inputs, params.loss, params.f_scale, level, params.speed_knot_s)
    cv: dict[str, Any] | None = None
    rigid_fit: dict[str, Any] | None = None  # the rigid solution, when terms replace it
    if params.nongeometric == "auto":
        sp, sol, identifiability, cv, rigid_fit = cross_validated(
            session_problem(*args), inputs, robot.prismatic, payloads, params.cv_folds
        )
    else:
        terms = all_terms(robot.prismatic, nongeometric_kinds(params.nongeometric, payloads))
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
        "cv_folds": params.cv_folds,
        "speed_knot_spacing_s": None if spline is None else spline.spacing_s,
        "rows_down_weighted": sol.down_weighted,
        "f_scale_used": sol.f_scale,
    }
    if identifiability:
        summary["identifiability"] = identifiability
    if sp.problem.model.terms or cv:
        summary["nongeometric"] = {
            "setting": params.nongeometric,
            "terms": list(sp.problem.model.terms.names),
            "measured_payloads_kg": list(payloads),
            **({"cv": cv} if cv else {}),
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


def cross_validated(
    rigid: Any, inputs: Mapping[str, Any], prismatic: np.ndarray, payloads: tuple[float, ...],
    k: int,
) -> tuple[Any, Any, dict[str, Any], dict[str, Any], dict[str, Any] | None]:  # fmt: skip
    """``refine.nongeometric=auto``: the rigid problem ``rigid`` fitted from the design
    (exactly as before issue 27), then each further candidate of
    :data:`pipeline.refine.model_choice.CANDIDATES` whose terms the readings excite and
    the coordinates can carry (:func:`_too_few_for`), warm-started at the rigid solution
    (:func:`with_rigid_solution`); each scored by k-fold over blocks of the measurement
    order and the model chosen by :func:`pipeline.refine.model_choice.choose` (its rule
    there). A rigid chain that fits to rounding (noiseless data of a rigid robot) is kept
    without fitting the others. A session of more than
    :data:`~pipeline.refine.model_choice.CHOICE_POSITIONS` positions fits and scores the
    candidates on a subsample of its poses (:func:`_choice_problem`), the rigid chain
    refitted there from its solution on all, and fits the chosen one to every position
    (:func:`_fitted_to_all`; the record's ``positions``). Returns the chosen problem, its
    solution and identifiability summary, the record (``nongeometric.cv``), and the rigid
    solution when terms replace it (stage ``holdout`` compares with it)."""
    from pipeline.refine.model_choice import (
        CANDIDATES,
        choose,
        fits_to_rounding,
        harmonic_joints,
        record,
    )
    from pipeline.stages.refine_problem import with_terms

    sol, ident = fit_session(rigid, inputs)
    exact = fits_to_rounding(sol.chi2, sol.dof)
    on = rigid if exact else _choice_problem(rigid)  # a large session's subsample
    base = (sol, ident) if on is rigid else fit_session(on, inputs, (sol.x, sol.f_scale))
    fits = {"rigid": (on, *base)}
    asked: dict[str, Any] = {}  # each fitted candidate's terms, before independent_terms
    skipped: dict[str, str] = {}
    extrapolation = harmonic_joints(on.problem.model.theta, ~np.asarray(prismatic, bool))
    for name in CANDIDATES[1:]:
        terms = candidate_terms(name, prismatic, payloads, extrapolation)
        if exact:
            skipped[name] = "not fitted: the rigid chain fits the data to rounding"
            continue
        if "harmonic" in name and not terms.harmonic:
            skipped[name] = "not fitted: no joint's readings span enough of a turn for a harmonic"
            continue
        sp = with_terms(on, terms, inputs)
        same = [
            o for o, fit in fits.items() if fit[0].problem.model.terms == sp.problem.model.terms
        ]
        if not sp.problem.model.terms:
            skipped[name] = "not fitted: no term the readings excite"
        elif same:
            skipped[name] = f"not fitted: the same terms as {same[0]}"
        elif _too_few_for(sp):
            skipped[name] = "not fitted: too few coordinates (2 per parameter)"
        else:
            warm = (with_rigid_solution(sp, on, base[0].x), base[0].f_scale)
            fits[name] = (sp, *fit_session(sp, inputs, warm))
            asked[name] = terms
    scored = [_scored(name, *fit, k) for name, fit in fits.items()]
    choice = choose(scored)
    if choice.chosen == "rigid":
        sp, chosen, chosen_ident = rigid, sol, ident
    elif on is rigid:
        sp, chosen, chosen_ident = fits[choice.chosen]
    else:  # chosen on the subsample: fitted to every position from its solution there
        sp, chosen, chosen_ident = _fitted_to_all(rigid, sol, fits[choice.chosen],
                                                  asked[choice.chosen], inputs)  # fmt: skip
    rigid_fit = None
    if choice.chosen != "rigid":  # the rigid fit kept: the holdout compares with it
        rigid_fit = {
            "x": sol.x.tolist(),
            "noise_scale": sol.noise_scale,
            "held": [h["name"] for h in ident.get("held", [])],
        }
    cv = record(scored, choice, k, skipped)
    cv["harmonic_extrapolation"] = {f"j{j}": v for j, v in extrapolation.items()}
    if on is not rigid:
        cv["positions"] = {"chosen_on": len(on.problem.model.link),
                           "of": len(rigid.problem.model.link)}  # fmt: skip
    return sp, chosen, chosen_ident, cv, rigid_fit


def _choice_problem(rigid: Any) -> Any:
    """The session problem ``rigid`` on the positions its model is chosen on
    (:func:`pipeline.refine.model_choice.choice_rows`: a large pose set's subsample), or
    ``rigid`` itself (every position)."""
    from pipeline.refine.model_choice import choice_rows
    from pipeline.refine.solve import on_positions, takes_positions

    if not takes_positions(rigid.problem):
        return rigid
    keys = rigid.problem.block.keys
    rows = choice_rows(keys.column("sweep").to_numpy(), keys.column("step").to_numpy())
    return rigid if rows is None else replace(rigid, problem=on_positions(rigid.problem, rows))


def _fitted_to_all(
    rigid: Any, rigid_sol: Any, fit: tuple[Any, Any, dict[str, Any]], terms: Any,
    inputs: Mapping[str, Any],
) -> tuple[Any, Any, dict[str, Any]]:  # fmt: skip
    """The candidate chosen on a subsample (``fit``: its problem there, solution and
    identifiability; ``terms``: the terms it was asked for) fitted to every position of
    ``rigid``: started from its subsample solution when the whole session keeps the same
    parameters, else from the rigid solution ``rigid_sol`` with the terms at zero."""
    from pipeline.stages.refine_problem import with_terms

    sub, sub_sol = fit[0], fit[1]
    sp = with_terms(rigid, terms, inputs)
    if sp.names == sub.names:
        warm = (sub_sol.x, sub_sol.f_scale)
    else:
        warm = (with_rigid_solution(sp, rigid, rigid_sol.x), rigid_sol.f_scale)
    return (sp, *fit_session(sp, inputs, warm))


def candidate_terms(
    name: str, prismatic: np.ndarray, payloads: tuple[float, ...], extrapolation: dict[int, float]
) -> Any:
    """The terms of a candidate of ``refine.nongeometric=auto``: those of its kinds
    (:func:`nongeometric_kinds`), the harmonics only of joints whose readings span enough
    of a turn (``extrapolation``: per joint, :func:`pipeline.refine.model_choice.
    harmonic_extrapolation` at most :data:`~pipeline.refine.model_choice.
    HARMONIC_EXTRAPOLATION`)."""
    from pipeline.kinematics.nongeometric import all_terms
    from pipeline.refine.model_choice import HARMONIC_EXTRAPOLATION

    terms = all_terms(prismatic, nongeometric_kinds(name, payloads))
    covered = {j for j, v in extrapolation.items() if v <= HARMONIC_EXTRAPOLATION}
    return replace(terms, harmonic=tuple(h for h in terms.harmonic if h[0] in covered))


def _scored(name: str, sp: Any, sol: Any, ident: dict[str, Any], k: int) -> Any:
    """The cross-validation of one candidate's fit ``sol`` of ``sp`` (identifiability
    summary ``ident``): each fold of :func:`pipeline.refine.holdout.fold_of_blocks` held
    out, refit by one Gauss-Newton step from ``sol`` at its robust scale, the parameters
    the fit held staying held (:class:`pipeline.refine.holdout.StepRefit`), and scored
    on its held-out positions (:func:`pipeline.refine.holdout.kfold`) against what the
    fold's block measures there (:meth:`~pipeline.refine.holdout.StepRefit.
    measured_without`): a pose set's or a point sensor's positions; for raw ranges, the
    positions the ranges give with the sensor that fold calibrated without them. Measured
    on simulated sonic sweeps (100 points per sweep, seeds 1-6): scored against the
    positions the recorded sensor triangulates, the committed rigid robot2 and robot5
    took terms; against the full fit's sensor, 5 of 6 robots with a 0.3 mm compliance
    kept the rigid chain (a fold's chain and sensor move together); with the fold's own
    sensor 6 of 6 took the compliance and 6 of 6 rigid robots none."""
    from pipeline.refine.holdout import StepRefit, fold_mse, fold_of_blocks, kfold
    from pipeline.refine.model_choice import Scored, fits_to_rounding

    held = np.isin(np.array(sp.names), [h["name"] for h in ident.get("held", [])])
    problem = replace(sp.problem, held=held, f_scale=sol.f_scale)
    keys = problem.block.keys
    sweep, step = (keys.column(c).to_numpy() for c in ("sweep", "step"))
    noise_var = sol.noise_scale**2 if np.isfinite(sol.noise_scale) else 1.0
    refit = StepRefit(problem, sol.x, noise_var)
    measured = refit.measured
    cov_m = np.zeros((len(measured), 3, 3))  # the expected errors are not needed here
    fold = fold_of_blocks(sweep, step, k)
    out = kfold(problem.model, sweep, step, measured, cov_m, refit, k, fold,
                refit.measured_without, expected=False)  # fmt: skip
    n = np.bincount(out.fold, minlength=k)[:k]
    exact = fits_to_rounding(sol.chi2, sol.dof)
    n_terms = int((~held[problem.model.beta_slice]).sum())  # the identified ones
    return Scored(name, n_terms, fold_mse(out, k), n, exact)


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
    9,  # 3: the rods' speed spline fit on its normal equations (linear in the samples);
    # 4: the speed spline's knots chosen from the rods, every parameter in the summary,
    # single-cycle sonic positions weighed by the range noise law (level points);
    # 5: non-geometric terms (refine.nongeometric), the robust scale follows understated
    # noise (f_scale_used); 6: a target on the last link (plan.tool_targets) is one point
    # in every joint sweep that measures it, named tool/<target> (was poses/<target>);
    # 7: refine.nongeometric=auto chooses rigid, compliance, harmonic (joints covered over
    # enough of a turn) or both by k-fold over blocks of the measurement order
    # (refine.cv_folds, summary nongeometric.cv), no longer by a score test (issue 41);
    # 8: past 4,096 positions the chain is evaluated a chunk at a time, its sums and the
    # identifiability's QR over chunks, a large pose set's fit started on a subsample
    # (issue 45: the same minimum, other rounding; smaller sessions' bits unchanged);
    # 9: past 100,000 positions the model is chosen on evenly spaced poses and the chosen
    # one fitted to all (model_choice.CHOICE_POSITIONS; smaller sessions' bits unchanged)
    ("session", "joints", "positions", "frames", "ranges"),
    Params(),
    compute,
    "joint refinement of the chain (axis lines, target points) from all measurements",
)
