"""The evaluation report of a session: ``report/evaluation.md`` and its figures.

Index tables with improvement factors (beside the thesis's Tables 6-6 and
6-10/6-11), the mylar plot of the 2-D grid, 3-D error vectors and the 1-D
line-length errors. Everything comes from the evaluate_* stage tables.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import write_text_atomic
from pipeline.evaluation.indices import GRID3D_INDICES
from pipeline.evaluation.tasks import CATHETOMETER_CM, GRID2D_SHAPE
from pipeline.report import evaluation_figures as figs
from pipeline.report.evaluation_summary import summarize
from pipeline.report.identification import markdown_table
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table

#: Section 6.6.1 Table 6-6 (Robot 1), errors as printed: design, signature (cm).
THESIS_6_6 = ((-0.530, -0.050), (0.350, -0.125), (-0.290, -0.060), (0.325, -0.105),
              (-0.625, -0.040), (-0.275, -0.045))  # fmt: skip
#: Tables 6-10 (Robot 3) and 6-11 (Robot 5) in GRID3D_INDICES order: design, signature, factor.
THESIS_6_10 = ((0.071, 0.023, 3.09), (0.023, 0.006, 3.83), (0.019, 0.007, 2.71),
               (0.055, 0.077, 0.71), (0.096, 0.016, 6.00), (0.027, 0.013, 2.08),
               (-1.040, -0.096, 10.83), (-0.278, 0.229, 1.21), (-0.505, -0.238, 2.12),
               (0.153, -0.038, 4.00), (-0.157, 0.038, 4.14), (-0.067, -0.027, 2.50))  # fmt: skip
THESIS_6_11 = ((0.066, 0.023, 2.87), (0.022, 0.006, 3.67), (0.038, 0.009, 3.98),
               (0.139, 0.182, 0.76), (0.110, 0.016, 6.88), (0.079, 0.026, 3.04),
               (-0.974, -0.077, 12.65), (0.365, 0.226, 1.62), (0.271, -0.160, 1.69),
               (0.172, 0.000, -0.005), (-0.086, -0.005, 16.0), (-0.041, -0.014, 3.01))  # fmt: skip
MAGNIFY_2D = 50.0
MAGNIFY_3D = 50.0


def _factor(item: dict[str, Any]) -> str:
    f = item["improvement"]
    text = "∞" if f is None else f"{f:.2f}"
    return f"≥ {text}" if item["improvement_is_lower_bound"] else text


def _index_table(task: str, items: list[dict[str, Any]]) -> str:
    headers = ["index", "unit", "design", "signature", "improvement", "compensated",
               "improvement, compensated"]  # fmt: skip
    if task == "lines1d":
        headers += ["thesis Robot 1 design / signature (Table 6-6)"]
    if task == "grid3d":
        headers += ["thesis Robot 3 (Table 6-10)", "thesis Robot 5 (Table 6-11)"]
    rows = []
    grid3d_row = {name: k for k, (name, _, _) in enumerate(GRID3D_INDICES)}
    for k, it in enumerate(items):
        row = [it["name"], it["unit"], f"{it['design']:.4f}", f"{it['signature']:.4f}"]
        row.append(_factor(it))
        row.append("—" if it["compensated"] is None else f"{it['compensated']:.4f}")
        row.append(
            _factor(
                {
                    "improvement": it["improvement_compensated"],
                    "improvement_is_lower_bound": it["improvement_compensated_is_lower_bound"],
                }
            )
            if "improvement_compensated" in it
            else "—"
        )
        if task == "grid3d":
            j = grid3d_row[it["name"]]  # rows an arm cannot control are left out
            row += [" / ".join(f"{v:g}" for v in t[j]) for t in (THESIS_6_10, THESIS_6_11)]
        if task == "lines1d":
            row.append(" / ".join(f"{v:g}" for v in THESIS_6_6[k]) if k < len(THESIS_6_6) else "")
        rows.append(row)
    return markdown_table(headers, rows)


def _restricted_note(s: dict[str, Any]) -> str:
    """Why the orientation indices of an arm with fewer than six joints differ."""
    rot = [c for c in s["controlled"] if c.startswith("r")]
    dropped = [f"{t}: {', '.join(v['not_applicable'])}" for t, v in s["tasks"].items()
               if v["not_applicable"]]  # fmt: skip
    text = (
        f"This arm controls only {', '.join(s['controlled'])} of the tool pose (its task "
        "axes); both controllers solve those components in the taught workspace frame and "
        "the other rotation components are set by the arm's geometry and the fixture's "
        "tilt, alike for both. "
    )
    if rot:
        text += (
            f"Orientation indices use the controlled component(s) ({', '.join(rot)}) of the "
            "measured rotation vectors only (`_orientation_error_"
            + "".join(c[1] for c in rot)
            + "_deg`; relative ones as differences of those components). "
        )
    if dropped:
        text += "Not applicable, left out: " + "; ".join(dropped) + "."
    return text


def _positions(meas: list[dict[str, Any]], task: str, controller: str) -> np.ndarray:
    rows = sorted((m for m in meas if m["task"] == task and m["controller"] == controller),
                  key=lambda m: m["point"])  # fmt: skip
    return np.array([[m["x_cm"], m["y_cm"], m["z_cm"]] for m in rows], float)


def write_evaluation_report(session_dir: str | Path) -> Path:
    """Write ``report/evaluation.md`` and its figures; returns the markdown path."""
    sdir = Path(session_dir)
    out = sdir / "report"
    out.mkdir(exist_ok=True)
    s = summarize(sdir)
    meas = read_table(stage_path(sdir, "evaluate_measurements")).to_pylist()
    prog = read_table(stage_path(sdir, "evaluate_program")).to_pylist()
    want = {
        t: np.array([[r["x_cm"], r["y_cm"], r["z_cm"]] for r in prog
                     if r["task"] == t and r["controller"] == "design"], float)
        for t in s["tasks"]
    }  # fmt: skip
    rig = s["rig"]
    lines = [
        f"# Evaluation of {sdir.name}: design model against arm signature",
        "",
        "Grid-touching tasks of Sections 6.5, 6.6 and 7.2.1 (protocol: docs/evaluation.md). "
        f"Rig: {rig['mode']}, servo {rig['servo']}, instruments {rig['instruments']}. "
        "Improvement = |design| / |signature|; '≥' where the signature's reading is within half "
        "a resolution step of zero (the factor is then at least |design| / resolution). "
        "Thesis columns: design / signature / factor as printed. Compensated: the design "
        "controller (nominal model) driven to the targets `pipeline compensate` rewrites "
        "(docs/compensate.md); '—' where the recording has no compensated run.",
        "",
        markdown_table(
            ["task", "indices", "median improvement", "median improvement, compensated"],
            [
                [
                    t,
                    len(v["indices"]),
                    _factor(
                        {
                            "improvement": v["median_improvement"],
                            "improvement_is_lower_bound": False,
                        }
                    ),  # fmt: skip
                    _factor(
                        {
                            "improvement": v["median_improvement_compensated"],
                            "improvement_is_lower_bound": False,
                        }
                    )
                    if "median_improvement_compensated" in v
                    else "—",
                ]
                for t, v in s["tasks"].items()
            ],
        ),
        "",
    ]
    if "grid12_signature_radial_cm" in s:
        rad = ", ".join(f"vertex {k}: {v:.4f}" for k, v in s["grid12_signature_radial_cm"].items())
        lines += [f"Signature radial errors of the 12-vertex grid (cm): {rad}.", ""]
    for name, why in s["skipped"].items():
        lines += [f"- **{name} skipped**: {why}.", ""]
    if len(s["controlled"]) < 6:
        lines += [_restricted_note(s), ""]
    titles = {
        "lines1d": "One-dimensional task (Table 6-6)",
        "grid2d": "Two-dimensional grid (Tables 6-8/6-9)",
        "grid3d": "Three-dimensional grid (Tables 6-10/6-11)",
        "grid12": "Simulated 12-vertex grid (Section 7.2.1, Table 7-1)",
    }
    for task, v in s["tasks"].items():
        lines += [f"## {titles[task]}", "", _index_table(task, v["indices"]), ""]
        if task == "lines1d":
            err = {c: np.array([i[c] for i in v["indices"]]) for c in figs.CONTROLLERS}
            figs.line_errors(err, CATHETOMETER_CM, out / "eval_lines1d.png")
            lines += ["![line-length errors](eval_lines1d.png)", ""]
        elif task == "grid2d":
            shape = (*GRID2D_SHAPE, 2)
            marks = {c: _positions(meas, task, c)[:, :2].reshape(shape) for c in figs.CONTROLLERS}
            figs.mylar(want[task][:, :2].reshape(shape), marks, MAGNIFY_2D, out / "eval_grid2d.png")
            lines += ["![mylar](eval_grid2d.png)", ""]
        else:
            act = {c: _positions(meas, task, c) for c in figs.CONTROLLERS}
            png = f"eval_{task}.png"
            figs.error_vectors(want[task], act, MAGNIFY_3D, titles[task].split(" (")[0], out / png)
            lines += [f"![error vectors]({png})", ""]
    path = out / "evaluation.md"
    write_text_atomic(path, "\n".join(lines))
    return path
