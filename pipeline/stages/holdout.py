"""Stage ``holdout``: the refined chain's error on positions the fit did not see.

With validation (``check``) configurations of the tool target (point-sensor sessions)
those are the held-out set: the refinement never used them, so the fitted chain predicts
them as it is. Otherwise k-fold over each joint sweep's steps (fold ``f``: steps ≡ f mod
k), each fold refit without its positions, warm-started at the full fit
(:mod:`pipeline.refine.holdout`); positions without a usable measurement (null) are not
scored. The measured position of a sonic session refined at its raw ranges is the one
the fold's own sensor (its microphones, frame and speed of sound, fitted without the
fold) triangulates from the held-out ranges, as the model choice's cross-validation
scores it; otherwise (and at check configurations) the recorded one. Each held-out position's
expected error combines its measurement covariance and the (refit's) parameter
covariance, both scaled by the fit's χ²/dof as the refinement scales its covariance.
Beside each, the design model's error at the same position (``design_error_cm``, issue
41): the design chain with its base and every measured point registered to the positions
the fit of that position used (the check configurations: every fit position; k-fold: the
fold's kept positions) (:func:`pipeline.refine.baseline.register_design_points`), so the
gain over the design is measured on data neither saw. A sonic session's design is
registered to, and scored at, its fold's own-sensor positions too: triangulated with the
recorded calibration, which a design registered to them absorbs and the self-calibrated
signature does not, the SCARA walk-through read 0.5× "the design" where the audit gives
31.6× (now 2.0×; robot3 14×, audited 78×). Its expected error counts the fold's chain and
sensor together (:meth:`pipeline.refine.holdout.StepRefit.difference_variance`). Zero
rows when the refinement is disabled.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.refine.kinematics import TOOL_POINT
from pipeline.stages.base import Stage, check_param

REFITS = ("step", "full")


@dataclass(frozen=True)
class Params:
    """``folds``: k of the k-fold (5: each refit keeps 80 % of every sweep). ``refit``:
    ``step``, one Gauss-Newton step from the full fit without the fold (robust weights of
    the full fit kept, :class:`pipeline.refine.holdout.StepRefit`): on a default Puma
    session its held-out RMS equals the full refit's to 0.1 % (0.02319 vs 0.02317 cm), at
    ~0.05 s a fold instead of ~2.7 s;
    ``full``, the solver's warm-started refit (:func:`pipeline.refine.solve.refit`)."""

    folds: int = 5
    refit: str = "step"

    def __post_init__(self) -> None:
        check_param(self, "holdout", "folds", 2 <= self.folds <= 100, "2 to 100")
        check_param(self, "holdout", "refit", self.refit in REFITS, " or ".join(REFITS))


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.solve import release_chunks

    try:
        return _compute(inputs, params)
    finally:  # the last fitted model's chunks are not kept past the stage
        release_chunks()


def _compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.stages.refine import (
        held_parameters,
        internal_factors,
        problem_params,
        refine_summary,
        refined_x,
    )
    from pipeline.stages.refine_problem import session_problem

    refine = inputs["refine"]
    if refine.num_rows == 0:
        return _table([], [], [], None, joints=inputs["joints"])
    summ = refine_summary(refine)
    sp = session_problem(inputs, **problem_params(summ))
    sp = dataclasses.replace(
        sp, problem=dataclasses.replace(sp.problem, held=held_parameters(refine))
    )
    f = internal_factors(refine)
    cov = np.outer(f, f) * np.array(refine.column("covariance").to_pylist(), float)
    scale = float(summ.get("noise_scale", 1.0)) ** 2
    keys, held, measured_by = _held_out(
        inputs, params, sp, refined_x(refine), cov, scale, summ.get("level") == "ranges"
    )
    rigid = None
    if sp.problem.model.terms:  # the same held-out positions without the terms (issue 27)
        rigid = _rigid_held_out(inputs, params, summ)
    ranges = summ.get("level") == "ranges"  # check rows keep the recorded triangulation
    design = None if ranges and measured_by is None else _design_held_out(inputs, sp, held,
                                                                           measured_by)  # fmt: skip
    return _table(*keys, held, rigid, design, inputs["joints"])


def _design_held_out(
    inputs: Mapping[str, Any], sp: Any, held: Any, measured_by: Any = None
) -> np.ndarray:
    """The registered design model's error (cm) at each held-out position of ``held``
    (module docstring); NaN where the positions it is registered to cannot fix it. With
    ``measured_by`` (a sonic session refined at its ranges) a fold's positions, kept and
    held out, are those its own sensor triangulates, as the signature's are scored."""
    from pipeline.errors import StageError
    from pipeline.refine.baseline import register_design_points
    from pipeline.signature.alignment import design_alignment
    from pipeline.stages.frames import chain_from_frames
    from pipeline.stages.positions import positions as xyz_of
    from pipeline.stages.refine_problem import rows_at
    from pipeline.stages.session import session_robot

    out = np.full(len(held.index), np.nan)
    if len(out) == 0:
        return out
    robot = session_robot(inputs["session"])
    model = sp.problem.model
    q_sig = chain_from_frames(inputs["frames"], robot.prismatic).joint_offsets
    base0 = design_alignment(chain_from_frames(inputs["chain"], robot.prismatic), robot)[0]
    pos = inputs["positions"]
    at = rows_at(sp.problem.block.keys, pos)
    m = np.vstack([xyz_of(pos), np.full((1, 3), np.nan)])[at]  # the block's positions
    fit = np.isfinite(m).all(axis=1)
    q = model.theta + q_sig
    design = robot.design_chain()
    if np.all(held.fold < 0):  # check configurations: registered to every fit position
        check = _check_rows(inputs, pos)
        if check is None:  # not reached: held-out rows of fold −1 are check rows
            return out
        rows, theta = check
        tool = model.point_names.index(TOOL_POINT)
        folds = [(fit, theta + q_sig, xyz_of(rows), np.full(len(theta), tool), np.arange(len(out)))]
    else:
        folds = [(fit & ~np.isin(np.arange(len(fit)), held.index[held.fold == f]),
                  q[held.index[held.fold == f]], m[held.index[held.fold == f]],
                  model.point[held.index[held.fold == f]], np.flatnonzero(held.fold == f))
                 for f in np.unique(held.fold)]  # fmt: skip
    link = _link_of_points(model)
    for f, (train, q_test, m_test, point_test, where) in zip(np.unique(held.fold), folds,
                                                              strict=True):  # fmt: skip
        if measured_by is not None and f >= 0:  # the fold's sensor measures both sides
            by = measured_by(~np.isin(np.arange(len(fit)), held.index[held.fold == f]))
            m, m_test = by, by[held.index[held.fold == f]]
            train = train & np.isfinite(m).all(axis=1)
        try:
            reg = register_design_points(design, q[train], m[train], model.link[train],
                                         model.point[train], base0)  # fmt: skip
        except (StageError, np.linalg.LinAlgError):  # a fold that cannot fix the design
            continue
        out[where] = reg.errors(q_test, m_test, link[point_test], point_test)
    return out


def _link_of_points(model: Any) -> np.ndarray:
    """The link (P,) each of ``model``'s points is fixed on, from its observations."""
    link = np.zeros(len(model.point_names), np.int64)
    link[model.point] = model.link
    return link


def _rigid_held_out(inputs: Mapping[str, Any], params: Params, summ: Any) -> Any:
    """The held-out errors of the rigid chain fitted to the same session (the fit the
    refinement makes with ``refine.nongeometric=none``): the refinement's own rigid
    solution when it recorded one (``refine.nongeometric=auto`` fits it first), else
    fitted here. Its covariance is not needed: only the errors are kept."""
    from pipeline.kinematics.nongeometric import NO_TERMS
    from pipeline.stages.refine import fit_session, problem_params
    from pipeline.stages.refine_problem import session_problem

    sp = session_problem(inputs, **{**problem_params(summ), "terms": NO_TERMS})
    recorded = summ.get("nongeometric", {}).get("rigid_fit")
    if recorded is not None:
        x, noise, names = np.array(recorded["x"], float), recorded["noise_scale"], recorded["held"]
    else:
        sol, ident = fit_session(sp, inputs)
        x, noise = sol.x, sol.noise_scale
        names = [h["name"] for h in ident.get("held", [])]
    held = np.isin(np.array(sp.names), names)
    sp = dataclasses.replace(sp, problem=dataclasses.replace(sp.problem, held=held))
    scale = noise**2 if np.isfinite(noise) else 1.0
    ranges = summ.get("level") == "ranges"
    return _held_out(inputs, params, sp, x, np.zeros((len(x), len(x))), scale, ranges)[1]


def _held_out(
    inputs: Mapping[str, Any], params: Params, sp: Any, x_hat: np.ndarray, cov: np.ndarray,
    scale: float, own_sensor: bool = False,
) -> tuple[tuple[list[Any], list[Any], list[Any]], Any, Any]:  # fmt: skip
    """The held-out positions' keys (sweep, step, target) and errors of the problem ``sp``
    fitted to ``x_hat`` with covariance ``cov`` (internal units), χ²/dof ``scale``: the
    check configurations when the session has them, else k-fold (module docstring); and
    with ``own_sensor`` (raw ranges fitted with their sensor) and k-fold, the fold's
    measured positions ``measured_by(keep)`` (K, 3) they are scored against: those the
    fold's own sensor triangulates, as the cross-validation of the model choice scores
    them (``pipeline.stages.refine._scored``), else None."""
    from pipeline.refine.holdout import StepRefit, check_configurations, kfold, measured_positions
    from pipeline.refine.solve import linearize, refit
    from pipeline.stages.positions import positions as xyz_of
    from pipeline.stages.refine_problem import payloads_at, rows_at

    model = sp.problem.model
    n_kin = model.n_params
    pos = inputs["positions"]
    check = _check_rows(inputs, pos)
    if check is not None:
        rows, theta = check
        cov_m = _measurement_covariances(inputs, rows, scale)
        sweep, step = (rows.column(c).to_numpy() for c in ("sweep", "step"))
        payload = np.nan_to_num(payloads_at(inputs["joints"], sweep, step), nan=0.0)
        held = check_configurations(
            model, theta, xyz_of(rows), cov_m, x_hat[:n_kin], cov[:n_kin, :n_kin], payload
        )
        cols = ("sweep", "step", "target")
        keys_ = tuple(rows.column(c).to_pylist() for c in cols)
        return keys_, held, None  # type: ignore[return-value]
    keys = sp.problem.block.keys
    at = rows_at(keys, pos)
    rows = pos.take(pa.array(at, mask=at < 0))  # a key without a position: a null row
    cov_m = _measurement_covariances(inputs, rows, scale)

    solved: dict[bytes, Any] = {}  # each fold's refit, by its kept positions

    def solve(keep: np.ndarray) -> Any:
        key = np.packbits(keep).tobytes()
        if key not in solved:
            solved[key] = refit(sp.problem, keep, x_hat)
        return solved[key]

    def full_refit(keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sol = solve(keep)
        return sol.x[:n_kin], sol.covariance[:n_kin, :n_kin]

    def full_measured(keep: np.ndarray) -> np.ndarray:
        """The positions the fold's refit sensor triangulates (:func:`measured_positions`)."""
        x = solve(keep).x
        whole = dataclasses.replace(sp.problem, keep=None)
        return measured_positions(linearize(whole, x), model.positions(x[:n_kin]))

    step_fit = StepRefit(sp.problem, x_hat, scale) if params.refit == "step" else None
    fold_fit = full_refit if step_fit is None else step_fit
    measured_by = None
    if own_sensor:  # the positions' covariances: as the fold's sensor triangulates them
        measured_by = full_measured if step_fit is None else step_fit.measured_without
        at_fit = StepRefit(sp.problem, x_hat, scale) if step_fit is None else step_fit
        cov_m = at_fit.measured_covariance

    sweep = keys.column("sweep").to_numpy()
    held = kfold(model, sweep, keys.column("step").to_numpy(), xyz_of(rows), cov_m, fold_fit,
                 params.folds, measured_by=measured_by)  # fmt: skip
    if own_sensor:  # the fold's chain and sensor move together (StepRefit.difference_variance)
        held = _own_sensor_expected(held, at_fit, len(sweep))
    k = held.index
    step = keys.column("step").to_numpy()[k].tolist()
    target = keys.column("target").take(pa.array(k)).to_pylist()  # not a row at a time
    return (sweep[k].tolist(), step, target), held, measured_by


def _own_sensor_expected(held: Any, at_fit: Any, K: int) -> Any:
    """``held`` with each position's expected error from the fold's chain and sensor
    together (:meth:`pipeline.refine.holdout.StepRefit.difference_variance`, at the full
    fit's linearization for a full refit too) beside its measurement's."""
    expected = held.expected_cm.copy()
    for f in np.unique(held.fold):
        on = held.fold == f
        var = at_fit.difference_variance(~np.isin(np.arange(K), held.index[on]))
        expected[on] = np.sqrt(var[held.index[on]] + held.measurement_cm[on] ** 2)
    return dataclasses.replace(held, expected_cm=expected)


def _measurement_covariances(inputs: Mapping[str, Any], rows: pa.Table, scale: float) -> np.ndarray:
    """What a held-out position's error holds besides the fit's: its covariance scaled by
    the fit's χ²/dof ``scale``; where the fit left unmodelled error (stage
    ``uncertainty``'s ``sigma_unmodelled_cm``, issue 41), the covariance as stated and
    that error's ``u²/3`` per axis instead (the arm's error the model leaves out, measured
    on the fit's raw residuals, not the robust χ²'s scale)."""
    unc = inputs.get("uncertainty")
    u, stated = 0.0, True
    if unc is not None and unc.num_rows and "sigma_unmodelled_cm" in unc.column_names:
        u = float(unc.column("sigma_unmodelled_cm").to_numpy()[0])
        stated = unc.column("unmodelled_p_value")[0].as_py() is not None
    if not u > 0:
        return scale * _covariances(inputs, rows)
    # without a stated noise the points' 1 cm weights are no covariance: the residual is all
    cov = _covariances(inputs, rows) if stated else np.zeros((rows.num_rows, 3, 3))
    return cov + (u**2 / 3.0) * np.eye(3)


def _covariances(inputs: Mapping[str, Any], rows: pa.Table) -> np.ndarray:
    """The positions' covariances (m, 3, 3) as the refinement weighs them (sonic: the
    trilateration covariance of the digitizer's geometry)."""
    from pipeline.stages.refine_problem import table_covariances
    from pipeline.stages.session import session_geometry

    return table_covariances(rows, session_geometry(inputs["session"]))


def _check_rows(inputs: Mapping[str, Any], pos: pa.Table) -> tuple[pa.Table, np.ndarray] | None:
    """The usable check positions of the tool target and their θ (m, n), or None."""
    import pyarrow.compute as pc

    from pipeline.stages.frames import chain_from_frames, readings_at
    from pipeline.stages.positions import positions as xyz_of
    from pipeline.stages.recording import CHECK_SWEEP
    from pipeline.stages.session import session_plan, session_robot
    from pipeline.stages.validation import tool_target
    from pipeline.units import joints_to_internal

    target = tool_target(session_plan(inputs["session"]), pos)
    rows = pos.filter(pc.and_(pc.equal(pos.column("sweep"), CHECK_SWEEP),
                              pc.equal(pos.column("target"), target)))  # fmt: skip
    rows = rows.filter(pa.array(np.isfinite(xyz_of(rows)).all(axis=1)))
    if rows.num_rows == 0:
        return None
    robot = session_robot(inputs["session"])
    n, pris = robot.n_joints, robot.prismatic
    q = readings_at(inputs["joints"], CHECK_SWEEP, rows.column("step").to_numpy(), n, pris)
    q_sig = chain_from_frames(inputs["frames"], pris).joint_offsets
    return rows, joints_to_internal(q, pris) - q_sig


def _table(
    sweep: list[Any], step: list[Any], target: list[Any], held: Any, rigid: Any = None,
    design: np.ndarray | None = None, joints: pa.Table | None = None,
) -> pa.Table:  # fmt: skip
    from pipeline.stages.joints import sources_at

    empty = np.zeros(0)
    design = np.full(len(sweep), np.nan) if design is None else design
    if rigid is not None and not np.array_equal(rigid.index, held.index):
        raise ValueError("holdout: the rigid fit's held-out positions differ")  # a bug
    rigid_error = np.full(len(sweep), np.nan) if rigid is None else rigid.error_cm
    return pa.table(
        {
            "sweep": pa.array(sweep, pa.int32()),
            "step": pa.array(step, pa.int32()),
            "target": pa.array(target, pa.string()),
            "fold": pa.array(empty if held is None else held.fold, pa.int32()),
            "error_cm": pa.array(empty if held is None else held.error_cm, pa.float64()),
            "expected_cm": pa.array(empty if held is None else held.expected_cm, pa.float64()),
            "measurement_cm": pa.array(
                empty if held is None else held.measurement_cm, pa.float64()
            ),
            "rigid_error_cm": pa.array(rigid_error, pa.float64(), mask=np.isnan(rigid_error)),
            "design_error_cm": pa.array(design, pa.float64(), mask=np.isnan(design)),
            **sources_at(joints, np.array(sweep, np.int64), np.array(step, np.int64)),
        }
    )


#: The sonic session's stage: the raw ranges too (level ``ranges`` rebuilds its problem).
STAGE = Stage(
    "holdout",
    8,  # 2: the folds' normal equations by the solver's structured products;
    # 3: the problem rebuilt with every refine.* parameter (speed_knot_s crashed it), and
    # single-cycle sonic positions' covariances from the range noise law (issue 33);
    # 4: rigid_error_cm, the same positions held out of the rigid fit (issue 27);
    # 5: design_error_cm, the registered design model at the same positions, and the
    # expected error with the fit's unmodelled error (issue 41); 6: source_file and
    # source_line of an imported row (issue 42); 7: a sonic session refined at its ranges
    # scored, and its design registered, at the positions each fold's own sensor
    # triangulates (issue 41); 8: past 4,096 positions the folds' normal equations summed
    # over chunks of positions in one pass, the problem's start points likewise (issue 45:
    # other rounding; smaller sessions' bits unchanged)
    ("session", "refine", "positions", "joints", "frames", "chain", "uncertainty", "ranges"),
    Params(),
    compute,
    "held-out position errors of the refined chain (k-fold or check configurations)",
)
#: A point-sensor session's (module ``holdout_points``): no ranges recorded.
POINTS_STAGE = dataclasses.replace(STAGE, inputs=STAGE.inputs[:-1])
