"""The report of a camera session (issue 39): ``report/report.md`` from stage ``camera_fit``.

Every number comes from the stage table and its summary: the fit (status, images, points,
rms reprojection), the parameters the images could not identify (held, with the line
that says what to measure), the lens with its σ, the hand-eye transforms as fitted (the
tool's point and rotation in the sensor frame at q̄^s) and OpenCV's closed-form start
beside them, the reprojection error of every image, and the figure of every point's
residual vector on the image plane (stage ``camera_residuals``, magnified).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import write_text_atomic
from pipeline.report.figures import panel_figure, save_png
from pipeline.report.identification import markdown_table
from pipeline.stages.camera_fit import camera_summary
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table


def _rows(table: Any, group: str) -> list[list[str]]:
    return [
        [r["name"], r["unit"] or "—", f"{r['start']:.6g}", f"{r['value']:.6g}", f"{r['sigma']:.3g}"]
        for r in table.to_pylist()
        if r["group"] == group
    ]


def residual_figure(table: Any, width_px: int, height_px: int, path: Path) -> tuple[Path, float]:
    """Every detected point's residual as an arrow on the image plane, magnified so that
    the largest is a twentieth of the image's width; the PNG and the magnification."""
    u, v = table.column("u_px").to_numpy(), table.column("v_px").to_numpy()
    du, dv = table.column("du_px").to_numpy(), table.column("dv_px").to_numpy()
    largest = float(np.max(np.hypot(du, dv))) if len(du) else 0.0
    gain = width_px / 20.0 / largest if largest > 0 else 1.0
    fig, (ax,) = panel_figure(1)
    ax.quiver(u, v, du * gain, dv * gain, angles="xy", scale_units="xy", scale=1.0,
              width=0.002)  # fmt: skip
    ax.set_xlim(0, width_px)
    ax.set_ylim(height_px, 0)  # v down, as in the image
    ax.set_aspect("equal")
    ax.set_title(f"reprojection residuals x {gain:.3g}")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    return save_png(fig, path), gain


def write_camera_report(session_dir: str | Path) -> Path:
    """Write ``report/report.md`` of a camera session whose ``camera_fit`` stage ran."""
    sdir = Path(session_dir)
    table = read_table(stage_path(sdir, "camera_fit"))
    s = camera_summary(table)
    head = ("parameter", "unit", "start", "fitted", "σ")
    images = s["images"]
    worst = max(images, key=lambda r: r[2]) if images else None
    parts = [
        f"# Camera calibration: {sdir.resolve().name}\n\n"
        f"Set-up **{s['setup']}**, intrinsics **{s['intrinsics']}**: {s['n_images']} images, "
        f"{s['n_points']} points; {s['status']} in {s['iterations']} iterations "
        f"({s['message']}); rms reprojection **{s['rms_px']:.3g} px**, χ²/dof "
        f"{s['chi2'] / max(s['dof'], 1):.3f}.",
        *([f"**Held:** {s['warning']}"] if s.get("warning") else []),
        "## Lens (OpenCV's names)\n\n" + markdown_table(head, _rows(table, "intrinsics")),
        "## Hand-eye: the body on the flange (sensor frame, at q̄^s)\n\n"
        "The sensor frame is the fixed body's (the camera eye-to-hand, the target "
        "eye-in-hand); the fixed hand-eye transform is joint 1's axis line in it "
        "(`axis` rows of `stages/camera_fit.arrow`).\n\n"
        + markdown_table(head, _rows(table, "point") + _rows(table, "tool_rotation")),
        "## Reprojection per image\n\n"
        + (f"Largest rms: image {worst[0]}, {worst[2]:.3f} px.\n\n" if worst else "")
        + markdown_table(
            ("image", "points", "rms px", "largest px"),
            [[i, n, f"{r:.3f}", f"{w:.3f}"] for i, n, r, w in images],
        ),  # fmt: skip
    ]
    out = sdir / "report" / "report.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    residuals = stage_path(sdir, "camera_residuals")
    if residuals.is_file():
        session = read_table(stage_path(sdir, "session"))
        lens = json.loads(session.column("rig_json")[0].as_py())["camera"]
        figure = out.parent / "camera_residuals.png"
        png, gain = residual_figure(read_table(residuals), lens["width_px"], lens["height_px"],
                                    figure)  # fmt: skip
        parts.append(
            "## Residuals on the image plane\n\nEvery detected point's residual (predicted − "
            f"detected), magnified {gain:.3g}×.\n\n![]({png.name})"
        )
        if worst:  # the worst image itself, when the recording references it (issue 40)
            from pipeline.report.camera_worst import worst_image_section

            section = worst_image_section(sdir, read_table(residuals), worst[0], out.parent)
            parts.extend([section] if section else [])
    parts[1:1] = _signature_parts(sdir, out.parent)
    write_text_atomic(out, "\n\n".join(parts) + "\n")
    return out


def _signature_parts(sdir: Path, folder: Path) -> list[str]:
    """The verdict (with the predicted error's map), the predicted accuracy and the
    held-out images, when the session's stage list has them."""
    from pipeline.report.verdict import error_map, verdict_section
    from pipeline.stages.uncertainty import summary

    if not stage_path(sdir, "verdict").is_file():
        return []
    unc = read_table(stage_path(sdir, "uncertainty"))
    u = summary(unc)
    out = [verdict_section(read_table(stage_path(sdir, "verdict")).to_pylist()[0],
                           error_map(unc, folder / "error_map.png"))]  # fmt: skip
    if u is not None:
        out.append(
            "## Predicted accuracy\n\nThe fit's covariance carried to the tool (the body on "
            "the flange) in the sensor frame, over 1,000 random configurations, mm: RMS "
            f"**{10 * u['sigma_total_rms_cm']:.3g}** (95 % {10 * u['sigma_total_p95_cm']:.3g}); "
            f"the parameters' part {10 * u['sigma_position_rms_cm']:.3g}, of which "
            f"{10 * u['sigma_position_aligned_rms_cm']:.3g} is not placement (base and tool); "
            f"unmodelled {10 * u['sigma_unmodelled_rms_cm']:.3g} (the pixel residual beyond "
            "the stated noise, at the target)."
        )
    hold = read_table(stage_path(sdir, "camera_holdout")).to_pylist()
    out.append(
        "## Held-out images\n\nThe last images in measurement order, the fit redone without "
        "them; the design chain's hand-eye fit of the same images beside it.\n\n"
        + markdown_table(
            ("image", "points", "rms px", "predicted px", "design chain px"),
            [
                [
                    r["image"],
                    r["points"],
                    f"{r['rms_px']:.3f}",
                    f"{r['expected_px']:.3f}",
                    f"{r['design_rms_px']:.3f}",
                ]
                for r in hold
            ],
        )  # fmt: skip
    )
    return out
