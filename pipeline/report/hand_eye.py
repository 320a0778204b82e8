"""The products of a camera session of flange poses without joints (issue 40): the camera
calibration file, the lens as ROS ``camera_info`` YAML, the report and the verdict line,
all from stage ``camera_fit`` (:mod:`pipeline.stages.hand_eye_fit`) and its residuals.

- ``camera_calibration.json``: both hand-eye transforms (translation cm, rotation as a
  quaternion w-first and as a 4 × 4 matrix, with σ of every parameter: the translation's
  in cm, the rotation's in degrees), the intrinsics with σ of every one beside the ones
  the user gave, the reprojection RMS of every image, the held-out images (stage
  ``hand_eye_holdout``: each image's RMS under the refit that did not see it, its
  prediction and the closed-form start's; the RMS of each over every point), and what the
  arm is (not calibrated);
- ``camera_info.yaml``: the fitted lens (:func:`pipeline.sensor.camera_info.camera_info_text`);
- ``report/report.md``: the same in tables, the worst image and the figure of every
  point's residual vector on the image plane;
- the verdict line: the in-sample RMS and the held-out one beside it (with its
  prediction), the lens fitted or given, and that the arm is not calibrated.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import write_text_atomic
from pipeline.report.camera import residual_figure
from pipeline.report.camera_worst import worst_image_section
from pipeline.report.identification import markdown_table
from pipeline.stages.camera_fit import camera_summary
from pipeline.stages.hand_eye_holdout import holdout_summary
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table

RESULT_FILE, CAMERA_INFO_FILE = "camera_calibration.json", "camera_info.yaml"
#: The bodies of each set-up: (the fixed one in the base, the one on the flange).
BODIES = {"eye-to-hand": ("camera_in_base", "target_in_flange"),
          "eye-in-hand": ("target_in_base", "camera_in_flange")}  # fmt: skip


@dataclass(frozen=True)
class HandEyeProducts:
    """What :func:`write_hand_eye_products` wrote, and the verdict line."""

    result: Path
    camera_info: Path
    report: Path | None
    verdict: str


def _transform(T: Any, rows: list[dict[str, Any]], prefix: str) -> dict[str, Any]:
    """One hand-eye transform: its translation, rotation and their σ (``rows``: the fit's
    rows of its six parameters, named ``prefix.x`` … and ``prefix.rx`` …)."""
    from scipy.spatial.transform import Rotation

    T = np.asarray(T, float)
    xyzw = Rotation.from_matrix(T[:3, :3]).as_quat()
    sigma = {r["name"].split(".")[1]: r["sigma"] for r in rows if r["name"].startswith(prefix)}
    return {
        "translation_cm": [float(v) for v in T[:3, 3]],
        "rotation_wxyz": [float(xyzw[3]), *(float(v) for v in xyzw[:3])],
        "matrix_cm": T.tolist(),
        "sigma_translation_cm": [sigma[c] for c in "xyz"],
        "sigma_rotation_deg": [sigma[c] for c in ("rx", "ry", "rz")],
    }


def calibration_document(sdir: Path) -> dict[str, Any]:
    """The content of ``camera_calibration.json`` (module docstring)."""
    table = read_table(stage_path(sdir, "camera_fit"))
    s = camera_summary(table)
    rig = json.loads(read_table(stage_path(sdir, "session")).column("rig_json")[0].as_py())
    rows = table.to_pylist()
    fixed, flange = BODIES[s["setup"]]
    lens = [r for r in rows if r["group"] == "intrinsics"]
    hold = read_table(stage_path(sdir, "hand_eye_holdout"))
    return {
        "format": "armsig.camera_calibration", "version": 2, "setup": s["setup"],
        "arm": s["arm"], "intrinsics_mode": s["intrinsics"],
        "image_size_px": [rig["camera"]["width_px"], rig["camera"]["height_px"]],
        "intrinsics": {r["name"].split(".")[1]: r["value"] for r in lens},
        "sigma_intrinsics": {r["name"].split(".")[1]: r["sigma"] for r in lens},
        "intrinsics_given": {k: rig["camera"].get(k, 0.0) for k in
                             ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")},
        fixed: _transform(s["fixed_in_base_cm"], rows, "fixed"),
        flange: {**_transform(s["tool_in_flange_cm"], [
            {**r, "name": r["name"].replace("tool_rot.", "tool.")} for r in rows
            if r["group"] in ("point", "tool_rotation")], "tool")},
        "rms_px": s["rms_px"], "n_images": s["n_images"], "n_points": s["n_points"],
        "images": [{"image": i, "points": n, "rms_px": r, "largest_px": w}
                   for i, n, r, w in s["images"]],
        "fit": {k: s[k] for k in ("status", "message", "iterations", "loss", "f_scale",
                                  "chi2", "dof")},
        "held_out": {**holdout_summary(hold), "images": hold.to_pylist()},
    }  # fmt: skip


def verdict_line(sdir: Path, doc: dict[str, Any]) -> str:
    """The last line of ``identify``: the camera's fit, and that the arm is not calibrated."""
    fitted = {"fitted": "hand-eye and lens fitted", "fixed": "hand-eye fitted, lens as given",
              "prior": "hand-eye and lens fitted (the given lens a prior)"}  # fmt: skip
    h = doc["held_out"]
    held = (f"{h['rms_px']:.3g} px held out (predicted {h['expected_px']:.3g})"
            if h["folds"] else "none held out")  # fmt: skip
    return (
        f"{sdir.resolve().name}: CAMERA ONLY  {doc['rms_px']:.3g} px rms over "
        f"{doc['n_points']} points in {doc['n_images']} images, {held}, "
        f"{fitted[doc['intrinsics_mode']]}; the arm is not calibrated (flange poses, no "
        "joint readings)"
    )


def _held_out_section(h: dict[str, Any]) -> str:
    """The report's held-out images (stage ``hand_eye_holdout``)."""
    if not h["folds"]:
        return f"## Held-out images\n\nNone: {h['reason']}."
    rows = [
        [
            r["image"],
            r["fold"],
            r["points"],
            f"{r['rms_px']:.3f}",
            f"{r['expected_px']:.3f}",
            f"{r['start_rms_px']:.3f}",
        ]
        for r in h["images"]
    ]
    return (
        "## Held-out images\n\n"
        f"The images in {h['folds']} contiguous folds, each held out in turn and the "
        "calibration refitted on the others from its own closed-form start. Over every "
        f"point: **{h['rms_px']:.3f} px held out** against {h['in_sample_rms_px']:.3f} px "
        f"in the full fit; predicted {h['expected_px']:.3f} px (the refit's noise and "
        f"covariance); the closed-form start (OpenCV) {h['start_rms_px']:.3f} px. Held out "
        "well above the full fit is a calibration that follows its own images (an "
        "over-fitted lens) or errors its points share (the flange pose's own error): the "
        "prediction counts each point's noise as independent and sees neither.\n\n"
        + markdown_table(("image", "fold", "points", "rms px", "predicted px", "start px"),
                         rows)
    )  # fmt: skip


def _lens_rows(doc: dict[str, Any]) -> list[list[str]]:
    k, s, given = doc["intrinsics"], doc["sigma_intrinsics"], doc["intrinsics_given"]
    return [[n, f"{given[n]:.6g}", f"{k[n]:.6g}", f"{s[n]:.3g}"] for n in k]


def _pose_rows(doc: dict[str, Any]) -> list[list[str]]:
    out = []
    for name in (n for pair in BODIES.values() for n in pair if n in doc):
        t = doc[name]
        xyz = ", ".join(f"{v:.4f}" for v in t["translation_cm"])
        st = ", ".join(f"{v:.2g}" for v in t["sigma_translation_cm"])
        q = ", ".join(f"{v:.6f}" for v in t["rotation_wxyz"])
        sr = ", ".join(f"{v:.2g}" for v in t["sigma_rotation_deg"])
        out.append([name, xyz, st, q, sr])
    return out


def _report(sdir: Path, doc: dict[str, Any], verdict: str) -> Path:
    images = doc["images"]
    worst = max(images, key=lambda r: r["rms_px"])
    f = doc["fit"]
    parts = [
        f"# Camera calibration: {sdir.resolve().name}\n\n{verdict}\n\n"
        f"**The arm is {doc['arm']}.** Set-up **{doc['setup']}**, intrinsics "
        f"**{doc['intrinsics_mode']}**: {doc['n_images']} images, {doc['n_points']} points; "
        f"{f['status']} in {f['iterations']} iterations ({f['message']}); rms reprojection "
        f"**{doc['rms_px']:.3g} px**. Files: `{RESULT_FILE}`, `{CAMERA_INFO_FILE}`.",
        "## Lens (OpenCV's names), beside the one given\n\n"
        + markdown_table(("parameter", "given", "fitted", "σ"), _lens_rows(doc)),
        "## Hand-eye transforms\n\nTranslation (cm) and rotation (quaternion w, x, y, z) "
        "of each body; σ of the translation (cm) and of the rotation (deg, about the "
        "parent frame's axes for the body in the base, of the rotation vector for the "
        "body on the flange).\n\n"
        + markdown_table(("body", "x, y, z cm", "σ cm", "w, x, y, z", "σ deg"),
                         _pose_rows(doc)),
        "## Reprojection per image\n\n"
        f"Largest rms: image {worst['image']}, {worst['rms_px']:.3f} px.\n\n"
        + markdown_table(("image", "points", "rms px", "largest px"),
                         [[r["image"], r["points"], f"{r['rms_px']:.3f}",
                           f"{r['largest_px']:.3f}"] for r in images]),
        _held_out_section(doc["held_out"]),
    ]  # fmt: skip
    out = sdir / "report" / "report.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    w, h = doc["image_size_px"]
    residuals = read_table(stage_path(sdir, "camera_residuals"))
    png, gain = residual_figure(residuals, w, h, out.parent / "camera_residuals.png")
    parts.append("## Residuals on the image plane\n\nEvery detected point's residual "
                 f"(predicted − detected), magnified {gain:.3g}×.\n\n![]({png.name})")  # fmt: skip
    section = worst_image_section(sdir, residuals, int(worst["image"]), out.parent)
    parts.extend([section] if section else [])
    write_text_atomic(out, "\n\n".join(parts) + "\n")
    return out


def write_hand_eye_products(session_dir: str | Path, report: bool = True) -> HandEyeProducts:
    """Write the calibration file, ``camera_info.yaml`` and (``report``) the report of a
    session whose flange-pose camera fit ran (module docstring)."""
    from pipeline.sensor.camera import Intrinsics
    from pipeline.sensor.camera_info import camera_info_text

    sdir = Path(session_dir)
    doc = calibration_document(sdir)
    verdict = verdict_line(sdir, doc)
    result, info = sdir / RESULT_FILE, sdir / CAMERA_INFO_FILE
    write_text_atomic(result, json.dumps(doc, indent=1) + "\n")
    lens = Intrinsics(*doc["image_size_px"], **doc["intrinsics"])
    write_text_atomic(info, camera_info_text(lens))
    rep = _report(sdir, doc, verdict) if report else None
    return HandEyeProducts(result, info, rep, verdict)
