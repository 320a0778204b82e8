"""Stage ``uncertainty``: the refined signature's predicted tool error over the workspace.

The refinement's covariance of the chain parameters (its rows of groups ``axis``, the
``tool`` point and the non-geometric terms, the marginal of the kinematic part) propagated
to the tool, through the terms the signature applies (issue 27), at
``configurations`` random configurations within the joint limits (seeded, drawn as the
audit draws them), raw and after what the audit's base and tool re-alignment absorbs
(:mod:`pipeline.refine.uncertainty`, the formulas there). Beside that parameter part,
the error the model leaves out (issue 41): the fit's residual beyond the points' stated
noise (:mod:`pipeline.refine.unmodelled`), ``sigma_unmodelled_cm``, and the two together,
``sigma_total_cm = sqrt(aligned² + unmodelled²)``: how far the arm will be from where the
signature sends it. The fit's 3-D residuals are those of the refined chain at every usable
fit position of the ``positions`` table (a sonic session's triangulated ones). Zero rows
when the refinement is disabled (no covariance). Summaries (RMS, 95 %, max) come from the
rows: :func:`summary`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.errors import StageError
from pipeline.kinematics.nongeometric import KINDS
from pipeline.stages.base import Stage, check_param
from pipeline.stages.session import session_robot

#: Most configurations: (m, 6, P) error maps of ~30 parameters stay near 100 MB at 1e5.
MAX_CONFIGURATIONS = 100_000
#: Names of the tool point's rows of the ``refine`` table (``tool.x`` or ``tool_x_cm``).
_TOOL_ROW = re.compile(r"^tool[._]")


@dataclass(frozen=True)
class Params:
    """``configurations``: random configurations within the limits (the audit's 1000);
    ``seed``: their seed (the audit's 0, so both see the same configurations)."""

    configurations: int = 1000
    seed: int = 0

    def __post_init__(self) -> None:
        ok = 1 <= self.configurations <= MAX_CONFIGURATIONS
        check_param(self, "uncertainty", "configurations", ok, f"1 to {MAX_CONFIGURATIONS}")


def kinematic_covariance(
    refine: pa.Table, n_axis: int, covariance: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``x`` and ``Σ`` (internal units: rad, cm) of the axis parameters, the tool point (and
    rotation) and the non-geometric terms, in the order of :class:`ChainModel`'s
    parameters, rows picked from the ``refine`` table by group and name (joined by key,
    not position); ``covariance``: another covariance of the rows (internal units) to
    pick from, e.g. :func:`held_joint_covariance`."""
    group = refine.column("group").to_pylist()
    name = refine.column("name").to_pylist()
    axis = [i for i, g in enumerate(group) if g == "axis"]
    tool = [i for i, (g, s) in enumerate(zip(group, name, strict=True))
            if g == "point" and _TOOL_ROW.match(s)]  # fmt: skip
    tool += [i for i, g in enumerate(group) if g == "tool_rotation"]  # a 6-D tool (issue 26)
    terms = [i for i, g in enumerate(group) if g in KINDS]
    if len(axis) != n_axis or len(tool) not in (3, 6):
        raise StageError(
            "uncertainty: the refine table does not match the session's chain",
            expected=f"{n_axis} rows of group 'axis', 3 of the tool point (and 3 of its rotation)",
            got=f"{len(axis)} axis rows, {len(tool)} tool rows",
            fix="`pipeline identify SESSION --force` recomputes the refinement",
        )
    idx = np.array(axis + tool + terms)
    from pipeline.stages.refine import internal_factors, refined_x

    scale = internal_factors(refine)
    x = refined_x(refine)
    C = np.array(refine.column("covariance").to_pylist(), float) * np.outer(scale, scale)
    if covariance is not None:
        C = covariance
    return x[idx], C[np.ix_(idx, idx)]


def compute(inputs: Mapping[str, Any], params: Params) -> pa.Table:
    from pipeline.refine.uncertainty import predict_model, tool_poses

    refine = inputs["refine"]
    if refine.num_rows == 0:  # refinement disabled: no covariance
        return uncertainty_table(np.zeros((0, 3)), None, 0.0)
    robot = session_robot(inputs["session"])
    q = robot.random_configurations(params.configurations, params.seed)
    fit = _fit_model(inputs)  # the fit's own observations, for both parts below
    model, x, Sigma = _tool_model(inputs, q, held_joint_covariance(inputs, fit))
    pred = predict_model(model, x, Sigma, params.seed)
    return uncertainty_table(
        tool_poses(model, x)[0], pred, pred.max95_cm, fit_unmodelled(inputs, fit)
    )


def _tool_model(
    inputs: Mapping[str, Any], q: np.ndarray, covariance: np.ndarray | None = None
) -> tuple[Any, np.ndarray, np.ndarray]:
    """The refined chain's tool point at configurations ``q`` (m, n) (rad, cm) as a
    :class:`ChainModel` (no payload), its ``x`` and covariance ``Σ`` (internal units; from
    ``covariance`` of the refine rows when given, else the refinement's)."""
    from pipeline.kinematics.nongeometric import NO_TERMS
    from pipeline.refine.kinematics import TOOL_POINT, ChainModel
    from pipeline.stages.frames import chain_from_frames, matrices_from_columns
    from pipeline.stages.refine import nongeometric_model

    refine = inputs["refine"]
    robot = session_robot(inputs["session"])
    n, pris = robot.n_joints, robot.prismatic
    frames = inputs["frames"]
    m = len(q)
    q_sig = chain_from_frames(frames, pris).joint_offsets
    ng = nongeometric_model(refine, robot)
    model = ChainModel(
        frames0=matrices_from_columns(frames)[:n],
        prismatic=pris,
        link=np.full(m, n, np.int64),
        theta=q - q_sig,
        point=np.zeros(m, np.int64),
        point_names=(TOOL_POINT,),
        tool_rotation="tool_rotation" in refine.column("group").to_pylist(),
        terms=NO_TERMS if ng is None else ng.terms,
        design=None if ng is None else ng.design,
        reading_zero=q_sig,
        payload_kg=np.full(m, 0.0 if ng is None else ng.payload_kg),
    )
    x, Sigma = kinematic_covariance(refine, model.n_axis_params, covariance)
    return model, x, Sigma


def predicted_at(inputs: Mapping[str, Any], q: np.ndarray) -> np.ndarray | None:
    """The predicted tool error (m,) cm at configurations ``q`` (m, n) (rad, cm) of a
    session's committed tables (``session``, ``refine``, ``frames``, ``uncertainty``):
    the parameters' part there, aligned as over the workspace (the base and tool
    re-alignment fitted over these configurations), and the session's unmodelled part, in
    quadrature (module docstring); None when the refinement is disabled."""
    from pipeline.refine.uncertainty import predict_model

    if inputs["refine"].num_rows == 0 or inputs["uncertainty"].num_rows == 0:
        return None
    model, x, Sigma = _tool_model(inputs, np.asarray(q, float))
    aligned = predict_model(model, x, Sigma).position_aligned_cm
    u = float(inputs["uncertainty"].column("sigma_unmodelled_cm").to_numpy()[0])
    out: np.ndarray = np.sqrt(aligned**2 + u**2)
    return out


def _fit_model(inputs: Mapping[str, Any]) -> tuple[Any, np.ndarray, pa.Table]:
    """The refined chain observing the session's usable fit positions (finite, not of the
    check sweep): its :class:`ChainModel`, its ``x`` (joined to the ``refine`` rows by
    name) and those rows of ``positions``."""
    from pipeline.kinematics.nongeometric import Terms
    from pipeline.stages.positions import positions
    from pipeline.stages.refine import refine_summary, refined_x
    from pipeline.stages.refine_problem import model_for_keys
    from pipeline.sweeps import CHECK_SWEEP

    refine, pos, session = inputs["refine"], inputs["positions"], inputs["session"]
    use = np.isfinite(positions(pos)).all(axis=1) & (pos.column("sweep").to_numpy() != CHECK_SWEEP)
    rows = pos.filter(pa.array(use))
    names = refine.column("name").to_pylist()
    terms = Terms.from_names(refine_summary(refine).get("nongeometric", {}).get("terms", []))
    rotation = "tool_rotation" in refine.column("group").to_pylist()
    keys = rows.select(["sweep", "step", "target"])
    model = model_for_keys(keys, session, inputs["joints"], inputs["frames"], rotation, terms)
    at = {n: i for i, n in enumerate(names)}
    if any(n not in at for n in model.param_names):  # a bug: the tables disagree
        raise StageError(
            "uncertainty: the refine table lacks parameters of the session's chain model",
            expected=", ".join(model.param_names),
            got=", ".join(names),
            fix="`pipeline identify SESSION --force` recomputes the refinement",
        )
    return model, refined_x(refine)[[at[n] for n in model.param_names]], rows


def fit_unmodelled(inputs: Mapping[str, Any], fit: Any = None) -> Any:
    """:class:`pipeline.refine.unmodelled.Unmodelled` of the refined chain's residuals at
    the session's usable fit positions (finite, not of the check sweep), judged by the
    refinement's χ² (none for an import without a stated σ: ``recorded_sigma_cm``); a
    point sensor's only: a sonic session's is 0 (below). ``fit``: :func:`_fit_model`'s,
    when already built."""
    from pipeline.refine.solve import chain_positions
    from pipeline.refine.unmodelled import Unmodelled, unmodelled_error
    from pipeline.stages.positions import positions, recorded_sigma_cm
    from pipeline.stages.refine import refine_summary
    from pipeline.stages.session import session_sensor

    model, x, rows = _fit_model(inputs) if fit is None else fit
    summ = refine_summary(inputs["refine"])
    r = positions(rows) - chain_positions(model, x, keep=False)  # a chunk at a time
    if session_sensor(inputs["session"]) == "sonic":
        # Not estimated: the triangulated positions' residuals exceed their covariance on
        # clean sessions too (0.026 against 0.0185 cm, seed 11), the ranges-level fit's
        # sensor terms; the ranges' χ² (outliers: 50) is the χ² rule's to judge. The
        # outlier fault's signature audits at 0.0059 cm, as a clean one.
        ok = np.isfinite(r).all(axis=1)
        rms = float(np.sqrt(np.mean(np.sum(r[ok] ** 2, axis=1)))) if ok.any() else float("nan")
        return Unmodelled(0.0, rms, None, int(ok.sum()))
    stated = recorded_sigma_cm(inputs["positions"]) is not None
    return unmodelled_error(r, model.n_params, summ["chi2"], summ["dof"], stated)


def held_joint_covariance(inputs: Mapping[str, Any], fit: Any = None) -> np.ndarray | None:
    """The refined parameters' covariance (refine-row order, internal units) with the held
    joints' reading errors shared by every position until the joint moves
    (:func:`pipeline.refine.held_joints.sweep_covariance`), for a point-sensor session
    with joint sweeps and a stated point noise; None otherwise (a pose set moves every
    joint at every pose; a sonic session's ranges have their own noise law; without a
    stated noise every point weighs 1 cm, no covariance). Scaled by the fit's χ²/dof where that is
    above 1 (noise understated), never below: a χ²/dof under 1 is the shared errors'
    doing, the residuals do not see what the held joints' points absorb (tracker sweeps
    read 0.56-0.66, and were audited at 2.0× their prediction, issue 41). ``fit``:
    :func:`_fit_model`'s, when already built."""
    from pipeline.refine.held_joints import sweep_covariance
    from pipeline.stages.positions import recorded_sigma_cm
    from pipeline.stages.refine import refine_summary
    from pipeline.stages.refine_problem import table_covariances
    from pipeline.stages.session import session_sensor

    refine = inputs["refine"]
    summ = refine_summary(refine)
    if session_sensor(inputs["session"]) == "sonic" or summ.get("level") != "points":
        return None
    if recorded_sigma_cm(inputs["positions"]) is None:  # 1 cm weights are no noise to share
        return None
    model, x, rows = _fit_model(inputs) if fit is None else fit
    sweep = rows.column("sweep").to_numpy().astype(np.int64)
    if not (sweep >= 1).any():
        return None
    order = np.argsort(_measured_at(inputs["joints"], rows), kind="stable")
    cov = table_covariances(rows)[order]
    robot = session_robot(inputs["session"])
    sub = model.observing(order)
    _, Sigma = sweep_covariance(sub, x, robot, cov, sweep[order])
    Sigma *= max(1.0, float(summ["chi2"]) / float(summ["dof"]))
    names = refine.column("name").to_pylist()
    at = np.array([names.index(n) for n in model.param_names])
    out = np.full((len(names), len(names)), np.nan)
    out[np.ix_(at, at)] = Sigma
    return out


def _measured_at(joints: pa.Table, rows: pa.Table) -> np.ndarray:
    """When each row's configuration was read (s): the joints table's first time at its
    (sweep, step), the measuring order."""
    t: dict[tuple[int, int], float] = {}
    for sw, st, ts in zip(*(joints.column(c).to_pylist() for c in ("sweep", "step", "t_s")),
                          strict=True):  # fmt: skip
        t.setdefault((sw, st), ts)
    keys = zip(rows.column("sweep").to_pylist(), rows.column("step").to_pylist(), strict=True)
    return np.array([t.get(k, np.inf) for k in keys], float)


def uncertainty_table(
    p: np.ndarray, pred: Any, max95: float, unmodelled: Any = None, raw: bool = False
) -> pa.Table:
    """The stage's rows: tool positions ``p`` (m, 3), the :class:`Prediction` ``pred``,
    ``max95`` and the :class:`Unmodelled`; ``sigma_total_cm`` of the aligned parameters'
    part, or with ``raw`` of the raw one (a camera: its frames are physical, no alignment
    takes a part of the error away, :mod:`pipeline.stages.camera_uncertainty`)."""
    m = len(p)
    cols = ("position_cm", "position_aligned_cm", "orientation_deg", "orientation_aligned_deg")
    u = 0.0 if unmodelled is None else unmodelled.rms_cm
    aligned = np.zeros(0) if pred is None else pred.position_cm if raw else pred.position_aligned_cm

    def each(v: float | None) -> pa.Array:  # null, not NaN, where there is none
        none = v is None or not np.isfinite(v)
        return pa.array(np.full(m, 0.0 if none else v), pa.float64(), mask=np.full(m, none))

    return pa.table(
        {
            "configuration": pa.array(np.arange(m), pa.int32()),
            **{f"{a}_cm": pa.array(p[:, k], pa.float64()) for k, a in enumerate("xyz")},
            **{
                f"sigma_{c}": pa.array(np.zeros(0) if pred is None else getattr(pred, c))
                for c in cols
            },
            "sigma_unmodelled_cm": pa.array(np.full(len(aligned), u), pa.float64()),
            "sigma_total_cm": pa.array(np.sqrt(aligned**2 + u**2), pa.float64()),
            "max95_cm": pa.array(np.full(m, max95), pa.float64()),
            "fit_residual_rms_cm": each(None if unmodelled is None else unmodelled.residual_rms_cm),
            "unmodelled_p_value": each(None if unmodelled is None else unmodelled.p_value),
        }
    )


def summary(table: pa.Table) -> dict[str, float] | None:
    """RMS, 95th percentile and max of each σ column, and ``max95_cm``; None without rows."""
    if table.num_rows == 0:
        return None
    out = {"max95_cm": float(table.column("max95_cm")[0].as_py())}
    for c in ("fit_residual_rms_cm", "unmodelled_p_value"):
        if c in table.column_names:
            v = table.column(c)[0].as_py()
            out[c] = float("nan") if v is None else float(v)
    for c in table.column_names:
        if c.startswith("sigma_"):
            v = table.column(c).to_numpy()
            unit = c.rsplit("_", 1)[1]
            stem = c.removesuffix("_" + unit)
            out[f"{stem}_rms_{unit}"] = float(np.sqrt(np.mean(v**2)))
            out[f"{stem}_p95_{unit}"] = float(np.percentile(v, 95))
            out[f"{stem}_max_{unit}"] = float(v.max())
    return out


STAGE = Stage(
    "uncertainty",
    4,  # 2: the non-geometric terms' covariance and deflection in the prediction (issue 27);
    # 3: the unmodelled error beside the parameters' (sigma_unmodelled_cm, sigma_total_cm);
    # 4: a point-sensor sweep session's held joints' shared reading errors (issue 41)
    ("session", "refine", "frames", "positions", "joints"),
    Params(),
    compute,
    "predicted tool error of the refined signature over random configurations",
)
