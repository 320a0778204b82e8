"""The identification report of a session: ``report/report.md`` and its figures.

Every number comes from the stage tables in ``stages/`` (Chapter 6 layout:
Table 6-3 pseudo D-H parameters, Figures 6-11 to 6-13 residuals, Table 6-4
residual variances, Table 6-5 feature accuracies) plus data quality, an optional
audit against the simulator's truth, and the provenance of every stage.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.atomic import write_text_atomic
from pipeline.errors import StageError
from pipeline.report import figures
from pipeline.report.pose_set import pose_set_section
from pipeline.report.validation import validation_section
from pipeline.sensor.range_rows import unique_rows
from pipeline.stages.catalog import identification_names
from pipeline.stages.recording import CHECK_SWEEP, POSES_SWEEP
from pipeline.stages.runner import stage_path
from pipeline.stages.session import session_plan, session_robot, session_sensor
from pipeline.stages.tables import read_provenance, read_table

Row = dict[str, Any]
#: Stage tables the report reads (every stage's provenance is listed); ``compensate``
#: too when the session has it (sonic).
USED = ("session", "positions", "features", "residuals", "frames", "smodel", "dh")
#: Tables the report reads by columns, not as a Python dict a row: a pose set's grow with
#: it (a million poses' positions, validation and six million joint rows took 9.7 GB as
#: dicts, issue 45).
COLUMNAR = ("positions", "validation", "joints")
DASH = "—"


def _fmt(spec: str) -> Callable[[Any], str]:
    def fmt(v: Any) -> str:
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return DASH
        return format(v, spec)

    return fmt


cm, deg, sig, var = _fmt(".4f"), _fmt(".3f"), _fmt(".4g"), _fmt(".6f")


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A Markdown table (``|`` in cells escaped)."""

    def cell(v: Any) -> str:
        return str(v).replace("|", "\\|")

    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(lines)


def _load(sdir: Path) -> tuple[dict[str, Any], dict[str, dict[str, Any]], Any, dict[str, Any]]:
    session = stage_path(sdir, "session")
    names = identification_names(
        session_sensor(read_table(session)) if session.is_file() else "sonic"
    )
    missing = [n for n in names if not stage_path(sdir, n).is_file()]
    if missing:
        raise StageError(
            f"{sdir}: no identification to report (stage(s) {', '.join(missing)} have not run)",
            fix=f"run `pipeline identify {sdir}` first",
        )
    paths = {n: stage_path(sdir, n) for n in names}
    shown = (*USED, "compensate", "validation", "joints")
    tables = {n: read_table(paths[n]) for n in (*shown, "refine", "holdout") if n in paths}
    robot = session_robot(tables["session"])
    rows = {n: t if n in COLUMNAR else t.to_pylist() for n, t in tables.items() if n in shown}
    return rows, {n: read_provenance(p) for n, p in paths.items()}, robot, tables


def _pose_tables(tables: dict[str, Any]) -> dict[str, Any] | None:
    """The tables of the pose-set section when the session has a pose set, else None
    (``tables``: the stage tables :func:`_load` read, each once)."""
    if "poses" not in session_plan(tables["session"]):
        return None
    return {n: tables[n] for n in ("session", "positions", "joints", "frames", "refine")}


def _nongeometric_part(tables: dict[str, Any], robot: Any) -> list[str]:
    """The non-geometric section (:mod:`pipeline.report.nongeometric`) when the signature
    has such terms or ``refine.nongeometric=auto`` chose among them, with the readings of
    every configuration the fit used (``tables``: the stage tables :func:`_load` read)."""
    import pyarrow.compute as pc

    from pipeline.kinematics.nongeometric import KINDS
    from pipeline.report.nongeometric import nongeometric_section
    from pipeline.stages.frames import readings_at
    from pipeline.stages.refine import refine_summary

    refine = tables["refine"]
    chose = "cv" in refine_summary(refine).get("nongeometric", {})
    if not chose and not np.isin(refine.column("group").to_pylist(), KINDS).any():
        return []
    joints = tables["joints"]
    fitted = joints.filter(pc.not_equal(joints.column("sweep"), CHECK_SWEEP))
    sweep, step = (fitted.column(c).to_numpy().astype(np.int64) for c in ("sweep", "step"))
    keys = unique_rows(np.stack([sweep, step], axis=1))[0]  # by sweep, then step
    n, pris = robot.n_joints, robot.prismatic
    # one join per sweep (one per key took 0.9 s for 2,773 poses)
    q = np.vstack([readings_at(joints, int(s), keys[keys[:, 0] == s, 1], n, pris)
                   for s in np.unique(keys[:, 0])])  # fmt: skip
    holdout = tables["holdout"]
    return [nongeometric_section(refine, holdout, q, robot, markdown_table)]


def _summary(name: str, t: dict[str, Any], robot: Any, mode: str) -> str:
    pos, feats = t["positions"], t["features"]
    sweep, step = (pos.column(c).to_numpy().astype(np.int64) for c in ("sweep", "step"))
    sweeps = np.unique(sweep[sweep > 0])
    config_sweep = unique_rows(np.stack([sweep, step], axis=1))[0][:, 0]
    probe = int(np.sum(config_sweep == 0))
    check = int(np.sum(config_sweep == CHECK_SWEEP))
    poses = int(np.sum(config_sweep == POSES_SWEEP))
    warned = [f for f in feats if f["warnings"]]
    text = (
        f"Session **{name}** ({mode}) identifies the arm signature of a {robot.name} with "
        f"{robot.n_joints} joints from {len(config_sweep) - check} configurations "
        f"({len(sweeps)} joint sweeps, {probe} tool-probe configuration(s)"
        + (f", {poses} poses of a pose set) " if poses else ") ")
    )
    if "compensate" in t:
        total = {k: int(pos.column(k).to_numpy().sum())
                 for k in ("n_samples", "n_dropped", "n_rejected", "n_used")}  # fmt: skip
        text += (
            f"and {total['n_samples']} digitize cycles: "
            f"{total['n_dropped']} cycles were dropped by the compensation, "
            f"{total['n_rejected']} rejected as outliers, {total['n_used']} averaged. "
        )
    else:
        targets = sorted(set(pos.column("target").unique().to_pylist()))
        text += (
            f"and {pos.num_rows} measured target positions of a point sensor ({len(targets)} "
            f"target id(s): {', '.join(targets)})"
            + (f"; {check} validation configuration(s) were not used. " if check else ". ")
        )
    if not warned:
        return text + "No feature warnings."
    worst = max(warned, key=lambda f: f["sigma_normal_cm"] or 0.0)  # null: unknown
    return text + (
        f"{len(warned)} joint(s) carry feature warnings; the largest residuals "
        f"(σ_normal {cm(worst['sigma_normal_cm'])} cm) are on joint {worst['joint']}: "
        f"“{'; '.join(worst['warnings'])}”"
    )


def _sweep_cells(r: Row, robot: Any) -> list[Any]:
    """Joint, name, points and sweep (deg) or travel (cm) of a features row."""
    pris = r["type"] == "prismatic"
    extent = f"{cm(r['travel_cm'])} cm" if pris else f"{deg(r['sweep_deg'])}°"
    return [r["joint"], robot.joints[r["joint"] - 1].name, r["n_points"], extent]


def _expected_section(rows: list[Row], robot: Any) -> str:
    """Expected feature accuracy of every sweep and why (pipeline/features/expected.py)."""
    body = [
        [*_sweep_cells(r, robot), r["residual_dof"], f"{r['noise_gain']:.3g}",
         sig(r["expected_axis_deg"]), sig(r["expected_center_cm"]), r["expected_basis"]]
        for r in rows
    ]  # fmt: skip
    head = ["Joint", "Name", "Points", "Sweep / travel", "Residual dof", "Noise gain"]
    head += ["Axis σ (deg)", "Centre σ (cm)", "From"]
    return (
        "## Expected feature accuracy (6.12)/(6.13)\n\n"
        + markdown_table(head, body)
        + "\n\n(6.12) (axis) and (6.13) (centre) hold for revolute sweeps of at least 180° "
        "(B-3). Below 180°, and for prismatic sweeps, the table states the fitted noise "
        "(N − 3, resp. 2N − 4, degrees of freedom) propagated through the fits instead "
        "(*propagated*); with no residual degree of freedom (3 points on a revolute sweep) the "
        "accuracy is *unknown*, not 0. The noise gain is the features' error at the target per "
        "unit of point noise, from the geometry alone: above 1 a sweep is too short or too "
        "sparse to beat one measured point, and a feature warning says so, as it does when "
        "fewer than 8 degrees of freedom leave the noise itself uncertain by more than 2x."
    )


def _dh_section(sdir: Path, robot: Any) -> str:
    """The identified D-H table in the form ``pipeline export --format dh`` writes (issue
    42): Hayati's β on nearly parallel axes instead of a common normal far from the arm
    (the pseudo D-H of stage ``dh`` printed d = ±4,075 cm there), from the refined chain
    (stage ``chain``; a session without it: ``frames``)."""
    from pipeline.kinematics.dh_table import dh_table_from_chain
    from pipeline.stages.frames import chain_from_frames

    path = next(p for n in ("chain", "frames") if (p := stage_path(sdir, n)).is_file())
    t = dh_table_from_chain(chain_from_frames(read_table(path), robot.prismatic))
    body = []
    for i, j in enumerate(robot.joints):
        body.append(
            [i + 1, j.name, f"d{i + 1}" if j.prismatic else f"θ{i + 1}",
             deg(np.degrees(t.theta[i])), deg(j.dh.theta_deg), cm(t.d[i]), cm(j.dh.d_cm),
             cm(t.a[i]), cm(j.dh.a_cm), deg(np.degrees(t.alpha[i])), deg(j.dh.alpha_deg),
             deg(np.degrees(t.beta[i])) if t.hayati[i] else DASH]
        )  # fmt: skip
    head = ["Joint", "Name", "Variable", "θ (deg)", "design θ", "d (cm)", "design d"]
    head += ["a (cm)", "design a", "α (deg)", "design α", "β (deg)"]
    return (
        "## Identified Denavit-Hartenberg parameters (as `pipeline export --format dh`)\n\n"
        + markdown_table(head, body)
        + "\n\nThe table `pipeline export --format dh` writes: A_i = Rot(z, θ) Trans(0, 0, d) "
        "Trans(a, 0, 0) Rot(x, α) Rot(y, β). Nearly parallel consecutive axes get Hayati's β "
        "(a rotation about y) instead of a common normal far from the arm, so d stays the "
        "size of the arm there (docs/export.md). For the variable of each joint (θ revolute, "
        "d prismatic) the table gives its value at encoder reading 0: θ = q + θ (d = q + d). "
        "The first row is measured from the sensor frame (the base as identified), so it "
        "differs from the design's by the base's placement. These numbers are for people: "
        "control uses the S-Model matrices B_i, not the D-H parameters."
    )


def _smodel_section(rows: list[Row], frames: list[Row], robot: Any) -> str:
    qs = {f["frame"]: f for f in frames if f["kind"] == "link"}
    body = []
    for r in rows:
        f, j = qs.get(r["link"], {}), robot.joints[r["link"] - 1]
        q = cm(f.get("q_signature_cm")) if j.prismatic else deg(f.get("q_signature_deg"))
        body.append(
            [r["link"], j.name, r["type"], f"{q} {j.unit}", deg(r["beta_deg"]),
             cm(r["d_bar_cm"]), cm(r["a_bar_cm"]), deg(r["alpha_bar_deg"]),
             deg(r["gamma_deg"]), cm(r["b_cm"])]
        )  # fmt: skip
    head = ["Link", "Name", "Type", "q̄ˢ", "β (deg)", "d̄ (cm)", "ā (cm)", "ᾱ (deg)"]
    return (
        "## S-Model link parameters (4.52)-(4.57)\n\n"
        + markdown_table(head + ["γ (deg)", "b (cm)"], body)
        + "\n\nβ and d̄ hold at the signature reading q̄ˢ of the joint."
    )


def _features_section(rows: list[Row], robot: Any) -> str:
    body = [
        [*_sweep_cells(r, robot), cm(r["radius_cm"]), sig(r["sigma_normal_cm"]),
         sig(r["sigma_radial_cm"]), sig(r["sigma_delta_deg"]),
         sig(r["sigma_delta_empirical_deg"]), sig(r["sigma_c_cm"]), sig(r["methods_angle_deg"])]
        for r in rows
    ]  # fmt: skip
    head = ["Joint", "Name", "Points", "Sweep / travel", "Radius (cm)", "σ_normal (cm)"]
    head += ["σ_radial (cm)", "σ_δ (deg)", "σ_δ (6.12) (deg)", "σ_c (cm)", "plane methods Δ (deg)"]
    warned = [f"- Joint {r['joint']}: {w}" for r in rows for w in r["warnings"]]
    return (
        "## Feature accuracies (cf. Table 6-5)\n\n"
        + markdown_table(head, body)
        + "\n\nσ_δ = max(σ_E, σ_F) from (6.9)-(6.10); σ_δ (6.12) and σ_c (6.13) use the "
        'thesis\' empirical constants and need enough sweep. "plane methods Δ" is the angle '
        "between the eigenvalue and repeated least-squares plane normals.\n\n"
        + _targets_section(rows)
        + "### Warnings\n\n"
        + ("\n".join(warned) if warned else "none")
    )


def _targets_section(rows: list[Row]) -> str:
    """Which targets of each sweep made its feature and why others did not (several
    targets per sweep only)."""
    if all(len(r["targets_used"]) + len(r["targets_not_used"]) <= 1 for r in rows):
        return ""
    body = [
        [r["joint"], ", ".join(r["targets_used"]), "; ".join(r["targets_not_used"]) or "none"]
        for r in rows
    ]
    return (
        "### Targets\n\n"
        + markdown_table(["Joint", "Used (best-conditioned first)", "Not used, and why"], body)
        + "\n\nThe used targets' planes and centres give one axis (pipeline/features/"
        "targets.py); radius, σ and points above are those of the first used target.\n\n"
    )


def _variance_section(res: list[figures.JointResiduals]) -> str:
    def stats(v: np.ndarray | None) -> list[str]:
        if v is None or len(v) < 2:
            return [DASH, DASH]
        s2 = float(np.var(v, ddof=1))
        return [var(s2), cm(math.sqrt(s2))]

    body = [[j.joint, j.name, len(j.normal), *stats(j.normal), *stats(j.radial)] for j in res]
    head = ["Joint", "Name", "n", "normal variance (cm²)", "normal stdev (cm)"]
    return (
        "## Residual variances (cf. Table 6-4)\n\n"
        + markdown_table(head + ["radial variance (cm²)", "radial stdev (cm)"], body)
        + "\n\nSample variances (n − 1) of the residuals table; prismatic joints have distances "
        "from the line of translation as normal residuals and no radial residuals."
    )


def _figures_section(paths: dict[str, Path]) -> str:
    captions = {
        # No markdown characters in a caption: it is set in emphasis (a `*` inside one
        # ends it early in pandoc, python-markdown and markdown-it).
        "residuals": "Normal residuals (stars) and radial residuals (circles) against the "
        "joint reading (cf. Figure 6-11).",
        "hist_normal": "Histograms of the normal residuals (cf. Figure 6-12).",
        "hist_radial": "Histograms of the radial residuals (cf. Figure 6-13).",
    }
    out = ["## Figures"]
    out += [f"![{captions[k]}]({p.name})\n\n*{captions[k]}*" for k, p in paths.items()]
    return "\n\n".join(out)


def _point_quality_section(pos: pa.Table) -> str:
    sweep, step = (pos.column(c).to_numpy().astype(np.int64) for c in ("sweep", "step"))
    target = np.asarray(pos.column("target").to_numpy(zero_copy_only=False))
    unusable = pos.column("x_cm").is_null().to_numpy(zero_copy_only=False)
    sigma = pos.column("sigma_cm").to_numpy(zero_copy_only=False).astype(float)  # NaN: none
    cov = pos.column("cov_xx_cm2").is_valid().to_numpy(zero_copy_only=False)
    body = []
    for s in np.unique(sweep):
        on = sweep == s
        have = sigma[on][np.isfinite(sigma[on])]
        body.append(
            [_sweep_label(int(s)), len(np.unique(step[on])), int(on.sum()),
             ", ".join(sorted(set(target[on].tolist()))), int(unusable[on].sum()),
             cm(float(np.median(have))) if len(have) else DASH, int(cov[on].sum())]
        )  # fmt: skip
    head = ["Sweep", "Configurations", "Points", "Targets", "Unusable"]
    head += ["Median σ (cm)", "Points with covariance"]
    return "## Data quality\n\n" + markdown_table(head, body)


def _sweep_label(s: int) -> str:
    return {0: "tool probe", CHECK_SWEEP: "validation (check)", POSES_SWEEP: "pose set"}.get(
        s, f"joint {s}"
    )


def _quality_section(tri: list[Row], comp: list[Row]) -> str:
    status = {s: Counter(r["status"] for r in comp if r["sweep"] == s) for s in {
        r["sweep"] for r in comp}}  # fmt: skip
    body = []
    for s in sorted({r["sweep"] for r in tri}):
        rows = [r for r in tri if r["sweep"] == s]
        total = {k: sum(r[k] for r in rows) for k in ("n_samples", "n_dropped", "n_rejected")}
        bad = ", ".join(f"{k} {n}" for k, n in sorted(status.get(s, {}).items()) if k != "ok")
        scatter = [r["scatter_cm"] for r in rows if r["scatter_cm"] is not None]
        unusable = sum(r["x_cm"] is None for r in rows)
        body.append(
            [_sweep_label(s), len(rows), total["n_samples"],
             total["n_dropped"], bad or "none", total["n_rejected"], unusable,
             cm(float(np.median(scatter))) if scatter else DASH,
             cm(max(scatter)) if scatter else DASH]
        )  # fmt: skip
    head = ["Sweep", "Configurations", "Cycles", "Dropped", "Compensation status"]
    head += ["Rejected outliers", "Unusable configurations", "Median scatter (cm)", "Max scatter"]
    return "## Data quality\n\n" + markdown_table(head, body)


def _audit_section(audit: dict[str, Any]) -> str:
    keys = ("max_position_cm", "rms_position_cm", "max_orientation_deg", "rms_orientation_deg")
    body = [[name, *(sig(audit[name][k]) for k in keys)] for name in ("signature", "design")]
    head = ["Model", "max position (cm)", "RMS position (cm)", "max orientation (deg)"]
    return (
        "## Audit against the simulator's truth\n\n"
        + markdown_table(head + ["RMS orientation (deg)"], body)
        + f"\n\nOver {audit['configurations']} random configurations after the best-fit base "
        f"and tool alignment, the design model's RMS position error is "
        f"{audit['improvement_rms_position']:.1f}× the signature's."
    )


def _convergence_section(sdir: Path) -> str:
    from pipeline.control.convergence import format_tables, realistic_tables

    head = "## Control: convergence on this signature (cf. Tables 5-1, 5-2)\n\n"
    if not (sdir / "signature.json").is_file():
        return head + "No `signature.json` yet: `pipeline identify` writes it, then this table."
    return (
        head + "Per-iteration base-frame error (desired minus reached) of one target pose "
        "inverted on this signature, starting from the design model's inverse "
        "(Section 5.4). `pipeline ik-convergence SESSION` adds the deliberately poor "
        "signature (6.8 cm at iteration 0); it refits a base alignment per candidate "
        "(~1.5 s), too slow to run on every identification.\n\n"
        "```\n" + format_tables(realistic_tables(sdir)).rstrip() + "\n```"
    )


def _provenance_section(prov: dict[str, dict[str, Any]]) -> str:
    body = [
        [name, p.get("stage_version", DASH), f"`{json.dumps(p.get('params', {}), sort_keys=True)}`",
         p.get("created", DASH), f"`{str(p.get('content_hash', ''))[:12]}`"]
        for name, p in prov.items()
    ]  # fmt: skip
    head = ["Stage", "Version", "Parameters", "Created", "Content hash"]
    return "## Stage provenance\n\n" + markdown_table(head, body)


def _verdict_parts(sdir: Path, prov: dict[str, dict[str, Any]], out: Path) -> list[str]:
    """The verdict section when the session's stages have one (refinement, issue 15)."""
    if "verdict" not in prov:
        return []
    from pipeline.report.verdict import error_map, verdict_section

    unc = read_table(stage_path(sdir, "uncertainty"))
    fig = error_map(unc, out / "uncertainty.png") if unc.num_rows else None
    return [verdict_section(read_table(stage_path(sdir, "verdict")).to_pylist()[0], fig)]


def _sweep_sections(t: dict[str, list[Row]], robot: Any, out: Path) -> list[str]:
    """The joint sweeps' sections (Tables 6-4, 6-5, Figures 6-11 to 6-13) and figures."""
    res = figures.joint_residuals(t["residuals"], robot)
    panels = figures.Panels(len(res))  # one figure, drawn three times
    figs = {"residuals": figures.residuals_vs_q(res, out / "residuals.png", panels)}
    figs["hist_normal"] = figures.residual_histograms(
        res, "normal", out / "hist_normal.png", panels
    )
    if any(j.radial is not None for j in res):
        figs["hist_radial"] = figures.residual_histograms(
            res, "radial", out / "hist_radial.png", panels
        )
    return [
        _features_section(t["features"], robot),
        _expected_section(t["features"], robot),
        _variance_section(res),
        _figures_section(figs),
    ]


def write_report(session_dir: str | Path, audit: dict[str, Any] | None = None) -> Path:
    """Write ``report/report.md`` and its PNG figures for an identified session.

    ``audit`` is :meth:`pipeline.rig.audit.AuditResult.to_dict` output, reported when given.
    Raises :class:`StageError` when a stage output is missing. Returns the report path.
    """
    sdir = Path(session_dir)
    t, prov, robot, tables = _load(sdir)
    out = sdir / "report"
    out.mkdir(parents=True, exist_ok=True)
    name, mode = sdir.resolve().name, t["session"][0]["mode"]
    pose_tables = _pose_tables(tables)
    sweeps = _sweep_sections(t, robot, out) if t["features"] else []
    parts = [
        f"# Arm signature identification: {name}\n\nRobot **{robot.name}**, mode **{mode}**.",
        *_verdict_parts(sdir, prov, out),
        _summary(name, t, robot, mode),
        *([] if pose_tables is None else [pose_set_section(pose_tables, out, markdown_table)]),
        *_nongeometric_part(tables, robot),
        _dh_section(sdir, robot),
        _smodel_section(t["smodel"], t["frames"], robot),
        *sweeps,
        _quality_section(t["positions"].to_pylist(), t["compensate"])  # sonic: small
        if "compensate" in t
        else _point_quality_section(t["positions"]),
        *([validation_section(t["validation"], t.get("joints"))] if "validation" in t else []),
        _convergence_section(sdir),
        *([_audit_section(audit)] if audit is not None else []),
        _provenance_section(prov),
    ]
    path = out / "report.md"
    write_text_atomic(path, "\n\n".join(parts) + "\n")
    return path
