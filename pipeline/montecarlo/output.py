"""Files of a Monte-Carlo run: Arrow tables and PNG figures per study.

``OUT/<study>/indices.arrow``  one row per (setting, robot, index)
``OUT/<study>/summary.arrow``  mean, std and standard errors per (setting, index)
``OUT/<study>/radial_std.png`` Figures 7-4 … 7-8 (radial error std at vertices 1, 4, 5, 8)
``OUT/<study>/std_grid.png``, ``mean_grid.png``  Appendix G (all indices)
``OUT/misalignment/lines.png`` Figure 7-3 (mean and 3σ band of the three lines)
``OUT/features/features.arrow``, ``features.png``  Section 6.6
``OUT/refine/rms.png``, ``gain.png``, ``calibration.png``  issue 15 (:mod:`.refine_report`)
``OUT/compliance/fits.png``, ``calibration.png``  issue 27 (:mod:`.compliance_report`)
``OUT/verdict/sessions.arrow``, ``summary.arrow``, ``rules.arrow``, ``ratio.png``  issue 41
                               (:mod:`.verdict_report`)

Each table carries ``schema_name`` and ``schema_version`` in its schema metadata and
``armsig.package_version`` beside its other provenance, as the stage tables do.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline import __version__
from pipeline.evaluation.grid12 import CORNER_VERTICES
from pipeline.montecarlo.engine import StudyResult
from pipeline.montecarlo.stats import indices_table, summary_table
from pipeline.report.figures import save_png
from pipeline.stages.tables import write_table

#: Version of the Monte-Carlo table layouts (``schema_version``); the swept parameter's
#: column is named per study (``sigma_e_deg``, ``points``, ...), the rest is fixed.
SCHEMA_VERSION = "1"
#: Studies with their own indices, figures and ``montecarlo.md`` section (not the 12-vertex
#: grid's), in the report's order: the module of each (``write_figures``, ``section``,
#: ``HEADING``).
OWN_REPORTS = {
    "refine": "refine_report",
    "compliance": "compliance_report",
    "verdict": "verdict_report",
}


def own_report(study: str) -> Any:
    """The report module of a study of :data:`OWN_REPORTS`."""
    import importlib

    return importlib.import_module(f"pipeline.montecarlo.{OWN_REPORTS[study]}")


def write_montecarlo_table(
    path: Path, table: Any, schema_name: str, provenance: dict[str, Any]
) -> None:
    """``table`` written as a stage table is: schema name and version, package version (every
    Monte-Carlo table)."""
    meta = dict(table.schema.metadata or {})
    meta.update({b"schema_name": schema_name.encode(), b"schema_version": SCHEMA_VERSION.encode()})
    prov = {**provenance, "package_version": __version__}
    write_table(path, table.replace_schema_metadata(meta), prov)


def _provenance(res: StudyResult) -> dict[str, Any]:
    st = res.study
    return {
        "study": st.name,
        "parameter": st.parameter,
        "settings": list(st.values),
        "robots": int(res.values.shape[1]),
        "seed": res.seed,
        "wall_s": round(res.wall_s, 3),
    }


def write_study(out_dir: Path, res: StudyResult) -> Path:
    """Tables and figures of one swept study under ``out_dir/<study>``; returns that folder."""
    st = res.study
    d = Path(out_dir) / st.name
    d.mkdir(parents=True, exist_ok=True)
    names, units = list(st.index_names), list(st.index_units)
    values = np.asarray(st.values, float)
    prov = _provenance(res)
    write_montecarlo_table(
        d / "indices.arrow",
        indices_table(st.name, st.parameter, st.parameter_unit, values, res.values, names, units),
        "montecarlo_indices",
        prov,
    )
    write_montecarlo_table(
        d / "summary.arrow",
        summary_table(
            st.name,
            st.parameter,
            st.parameter_unit,
            values,
            res.summary,
            names,
            units,
            list(st.index_signed),
        ),
        "montecarlo_summary",
        prov,
    )
    if st.name in OWN_REPORTS:  # not the 12-vertex grid's indices: its own figures
        own_report(st.name).write_figures(res, d)
        return d
    if st.name == "misalignment":
        _lines_figure(res, d / "lines.png")
    else:
        _radial_figure(res, d / "radial_std.png")
    _grid_figure(res, "std", d / "std_grid.png")
    _grid_figure(res, "mean", d / "mean_grid.png")
    return d


def _radial_figure(res: StudyResult, path: Path) -> Path:
    from matplotlib.figure import Figure

    st, sm = res.study, res.summary
    x = np.asarray(st.values, float)
    fig = Figure(figsize=(6.0, 4.2))
    fig.subplots_adjust(left=0.13, right=0.97, bottom=0.13, top=0.9)
    ax = fig.subplots()
    for v, marker in zip(CORNER_VERTICES, "osD^", strict=True):
        k = st.index_names.index(f"vertex{v}_radial_error_cm")
        ax.errorbar(x, sm.std[:, k], yerr=sm.se_std[:, k], marker=marker, ms=4, capsize=2,
                    label=f"vertex {v}")  # fmt: skip
    ax.set_xlabel(st.title)
    ax.set_ylabel("radial error std (cm)")
    ax.set_title(f"{st.name}: radial position error std, {res.values.shape[1]} robots")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_png(fig, path)


def _grid_figure(res: StudyResult, stat: str, path: Path) -> Path:
    from matplotlib.figure import Figure

    st, sm = res.study, res.summary
    x = np.asarray(st.values, float)
    k = len(st.index_names)
    cols = 6 if k > 6 else k
    rows = -(-k // cols)
    fig = Figure(figsize=(2.6 * cols, 2.0 * rows))
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.04, top=0.94, wspace=0.45, hspace=0.6)
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False).ravel())
    y_all = getattr(sm, stat)
    err_all = sm.se_std if stat == "std" else sm.se_mean
    for j, ax in enumerate(axes):
        if j >= k:
            ax.set_visible(False)
            continue
        ax.errorbar(x, y_all[:, j], yerr=err_all[:, j], marker="o", ms=2.5, capsize=1.5, lw=1)
        if stat == "mean":
            ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_title(st.index_names[j], fontsize=6.5)
        ax.tick_params(labelsize=6)
        ax.grid(alpha=0.3)
    what = "standard deviations" if stat == "std" else "means"
    fig.suptitle(
        f"{st.name}: performance index {what} vs {st.title} (± standard error), "
        f"{res.values.shape[1]} robots",
        fontsize=10,
    )
    return save_png(fig, path)


def _lines_figure(res: StudyResult, path: Path) -> Path:
    from matplotlib.figure import Figure

    st, sm = res.study, res.summary
    x = np.asarray(st.values, float)
    fig = Figure(figsize=(11.0, 3.6))
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.15, top=0.85, wspace=0.3)
    axes = fig.subplots(1, 3)
    labels = ("X (60 cm)", "Y (40 cm)", "Z (50 cm)")
    for j, (ax, label) in enumerate(zip(axes, labels, strict=True)):
        ax.errorbar(x, sm.mean[:, j], yerr=3.0 * sm.std[:, j], marker="o", ms=3, capsize=3)
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_title(f"{label} line")
        ax.set_xlabel(st.title)
        ax.set_ylabel("line length error (cm)")
        ax.grid(alpha=0.3)
    fig.suptitle(
        f"Signature control with a W_AC calibration error: mean and 3σ band, "
        f"{res.values.shape[1]} robots (cf. Figure 7-3)"
    )
    return save_png(fig, path)


def features_table(res: Any) -> Any:
    """The feature-accuracy study as an Arrow table (one row per X, N, σ)."""
    import pyarrow as pa

    deg = np.degrees

    def f(name: str, values: Any, unit: str, description: str) -> tuple[Any, Any]:
        field = pa.field(name, pa.float64(), metadata={"unit": unit, "description": description})
        return field, pa.array(np.asarray(values, float))

    cols = [
        f("sweep_deg", res.sweep_deg, "deg", "joint travel X"),
        f("points", res.points, "", "points per circle N"),
        f("sigma_cm", res.sigma_cm, "cm", "noise std per coordinate"),
        f("sigma_delta_empirical_deg", deg(res.sigma_delta_emp), "deg", "largest tilt std"),
        f("sigma_delta_se_deg", deg(res.sigma_delta_se), "deg", "its standard error"),
        f("sigma_delta_6_9_deg", deg(res.sigma_delta_69), "deg", "mean of max(σ_E, σ_F)"),
        f("sigma_delta_6_11_deg", deg(res.sigma_delta_611), "deg", "(6.11), full turn"),
        f("sigma_delta_6_12_deg", deg(res.sigma_delta_612), "deg", "(6.12), Stone's constants"),
        f("sigma_c_empirical_cm", res.sigma_c_emp, "cm", "largest in-plane center std"),
        f("sigma_c_se_cm", res.sigma_c_se, "cm", "its standard error"),
        f("sigma_c_6_13_cm", res.sigma_c_613, "cm", "(6.13), Stone's constants"),
    ]
    return pa.table([c for _, c in cols], schema=pa.schema([fd for fd, _ in cols]))


def write_features(out_dir: Path, res: Any) -> Path:
    """``OUT/features/features.arrow`` and ``features.png`` (empirical over formula)."""
    from matplotlib.figure import Figure

    d = Path(out_dir) / "features"
    d.mkdir(parents=True, exist_ok=True)
    prov = {
        "trials": res.trials,
        "radius_cm": res.radius_cm,
        "fit_6_12": list(res.fit_612),
        "fit_6_13": list(res.fit_613),
        "wall_s": round(res.wall_s, 3),
    }
    write_montecarlo_table(d / "features.arrow", features_table(res), "montecarlo_features", prov)
    fig = Figure(figsize=(10.0, 3.8))
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.14, top=0.86, wspace=0.25)
    ax1, ax2 = fig.subplots(1, 2)
    for n, marker in zip(sorted(set(res.points)), "os^", strict=False):
        sel = res.points == n
        ax1.plot(res.sweep_deg[sel], (res.sigma_delta_emp / res.sigma_delta_612)[sel], marker,
                 label=f"N = {int(n)}")  # fmt: skip
        ax2.plot(res.sweep_deg[sel], (res.sigma_c_emp / res.sigma_c_613)[sel], marker,
                 label=f"N = {int(n)}")  # fmt: skip
    for ax, title in ((ax1, "plane tilt: empirical / (6.12)"), (ax2, "center: empirical / (6.13)")):
        ax.axhline(1.0, color="0.5", lw=0.8)
        ax.set_xlabel("joint travel X (deg)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Feature accuracy, {res.trials} trials per point, R = {res.radius_cm:g} cm")
    save_png(fig, d / "features.png")
    return d
