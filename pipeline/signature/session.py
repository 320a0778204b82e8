"""A session's ``signature.json``: written from the committed identification stages (the
stage runner's product, under the session lock, in the run that commits them), its
state against those stages, and read back only while it matches them.
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline import __version__
from pipeline.atomic import write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.kinematics.nongeometric import KINDS
from pipeline.robots.description import description_to_dict
from pipeline.signature.alignment import design_alignment
from pipeline.signature.checks import FORMAT, FORMAT_VERSION
from pipeline.signature.file import (
    FILE_NAME,
    Signature,
    matrix_rows,
    nongeometric_section,
    read_signature_document,
    signature_from_document,
    signature_text,
    smodel_section,
)
from pipeline.stages.runner import committed_hashes, recorded_committed_outdated, stage_path
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_table

STALE = "signature.json does not match the session's stages"


def refinement_section(refine: pa.Table) -> dict[str, Any]:
    """The refinement's summary (stage ``refine``): whether it ran, its status and χ², and
    the sensor's fitted parameters (self-calibration) with their σ. ``verdict``: the
    verdict stage's row where the stage list has one (:func:`signature_document`), else
    null."""
    from pipeline.stages.refine import refine_summary

    summary = refine_summary(refine)
    enabled = bool(summary.get("enabled", False))
    keys = ("level", "status", "iterations", "chi2", "dof", "noise_scale", "chi2_recorded_sensor")
    out: dict[str, Any] = {"enabled": enabled}
    out.update({k: summary[k] for k in keys if enabled and k in summary})
    rows = refine.select(["group", "name", "unit", "value", "sigma"]).to_pylist()
    out["sensor_calibration"] = [
        {k: r[k] for k in ("name", "unit", "value", "sigma")}
        for r in rows
        if r["group"] not in ("axis", "point", *KINDS)
    ]
    out["verdict"] = None
    return out


def signature_document(session_dir: Path, hashes: dict[str, str | None]) -> dict[str, Any]:
    """The signature as a JSON-ready dict (without its digest), built from the session's
    stage tables, whose content hashes are ``hashes``."""
    from pipeline.kinematics.signature import pseudo_dh_from_chain
    from pipeline.stages.frames import chain_from_frames
    from pipeline.stages.refine import internal_factors, nongeometric_model
    from pipeline.units import joints_to_boundary

    session = read_table(stage_path(session_dir, "session"))
    robot = session_robot(session)
    pris = robot.prismatic
    chain = chain_from_frames(read_table(stage_path(session_dir, "chain")), pris)
    thesis = chain_from_frames(read_table(stage_path(session_dir, "frames")), pris)
    camera = read_table(stage_path(session_dir, "camera_fit")) if "camera_fit" in hashes else None
    if camera is not None:  # a camera session (issue 39): its fit is in pixels, no features
        from pipeline.stages.camera_chain import camera_refinement
        from pipeline.stages.camera_fit import camera_warning

        refine, refinement, features = None, camera_refinement(camera), []
        camera_warnings = [w for w in (camera_warning(camera),) if w is not None]
    else:
        camera_warnings = []
        refine = read_table(stage_path(session_dir, "refine"))
        refinement = refinement_section(refine)
        features = read_table(stage_path(session_dir, "features")).to_pylist()
    if hashes.get("verdict") is not None:  # the stage list holds the verdict
        refinement["verdict"] = read_table(stage_path(session_dir, "verdict")).to_pylist()[0]
    nongeometric = None if refine is None else nongeometric_model(refine, robot)
    pdh = pseudo_dh_from_chain(chain)
    X, Y, misfit = design_alignment(chain, robot)
    qs = joints_to_boundary(chain.joint_offsets, pris)
    off = joints_to_boundary(pdh.q_offset, pris)
    pseudo = []
    for i, j in enumerate(robot.joints):
        if j.prismatic:
            pseudo.append(
                {
                    "type": "prismatic",
                    "q_offset_cm": float(off[i]),
                    "theta_deg": float(np.degrees(pdh.theta[i])),
                    "a_cm": float(pdh.a[i]),
                    "alpha_deg": float(np.degrees(pdh.alpha[i])),
                }
            )
        else:
            pseudo.append(
                {
                    "type": "revolute",
                    "q_offset_deg": float(off[i]),
                    "d_cm": float(pdh.d[i]),
                    "a_cm": float(pdh.a[i]),
                    "alpha_deg": float(np.degrees(pdh.alpha[i])),
                }
            )
    doc: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "robot": robot.name,
        "session": session_dir.name,
        "frame": "sensor",
        "length_unit": "cm",
        "angle_unit": "deg",
        "joint_names": [j.name for j in robot.joints],
        "joint_types": [j.type for j in robot.joints],
        "joint_limits": robot.limits.tolist(),
        "encoder_resolution": robot.encoder_resolution.tolist(),
        "signature_configuration": [float(v) for v in qs],
        "smodel": smodel_section(chain),
        "model": "refined" if refinement["enabled"] else "smodel",
        "thesis_smodel": smodel_section(thesis),
        "refinement": refinement,
        "pseudo_dh": pseudo,
        "design_alignment": {
            "sensor_from_design_base": matrix_rows(X),
            "design_flange_to_signature_tool": matrix_rows(Y),
            "rms_misfit_cm": misfit,
        },
        "robot_description": description_to_dict(robot),
        "pseudo_dh_base": matrix_rows(pdh.base),
        "pseudo_dh_tool": matrix_rows(pdh.tool),
        "feature_accuracy": [
            {
                k: f[k]
                for k in (
                    "joint",
                    "n_points",
                    "sweep_deg",
                    "travel_cm",
                    "radius_cm",
                    "sigma_normal_cm",
                    "sigma_radial_cm",
                    "sigma_delta_deg",
                    "sigma_c_cm",
                    "methods_angle_deg",
                )
            }
            for f in features
        ],
        "warnings": [f"joint {f['joint']}: {w}" for f in features for w in f["warnings"]]
        + camera_warnings,
        "provenance": {
            "recording_sha256": session.column("recording_sha256")[0].as_py(),
            "stages": hashes,
            "package_version": __version__,
            "created": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        },
    }
    if camera is not None:
        from pipeline.stages.camera_chain import camera_section

        doc["camera"] = camera_section(session, camera, X, Y)
    if nongeometric is not None and refine is not None:
        rows = np.isin(refine.column("group").to_pylist(), KINDS)
        sigma = refine.column("sigma").to_numpy()[rows] * internal_factors(refine)[rows]
        doc["nongeometric"] = nongeometric_section(nongeometric, sigma)
    return doc


def signature_status(session_dir: Path, hashes: dict[str, str | None]) -> tuple[str, str]:
    """``(state, reason)`` of a session's signature.json against the content ``hashes`` of
    its committed identification stages: missing, stale (unreadable, or built from other
    stage outputs) or fresh."""
    state, reason, _ = _status(Path(session_dir) / FILE_NAME, hashes)
    return state, reason


def _status(path: Path, hashes: dict[str, str | None]) -> tuple[str, str, dict[str, Any] | None]:
    if not path.is_file():
        return "missing", "never written", None
    try:
        doc = read_signature_document(path)
    except ArmsigError as exc:
        why = exc.what.removeprefix(f"{path}: ") + (f" ({exc.got})" if exc.got else "")
        return "stale", why, None
    if doc["provenance"]["stages"] != hashes:
        why = "built from other stage outputs than the committed ones (interrupted run?)"
        return "stale", why, doc
    return "fresh", "matches the committed stages", doc


def write_signature(
    session_dir: str | Path, hashes: dict[str, str | None] | None = None, force: bool = False
) -> tuple[Path, dict[str, Any], bool]:
    """Write ``signature.json`` beside the recording (atomically) unless the file there is
    intact and built from the stage outputs with content ``hashes`` (default: the verified
    committed ones); return its path, its document and whether it was written.

    The stage runner calls this under the session lock after it commits the stages.
    """
    sdir = Path(session_dir)
    path = sdir / FILE_NAME
    current = committed_hashes(sdir) if hashes is None else hashes
    missing = [name for name, h in current.items() if h is None]
    if missing:
        raise ArmsigError(
            f"{sdir}: cannot write {FILE_NAME}: stage {missing[0]} is missing or damaged",
            fix=f"run `pipeline identify {sdir}`",
        )
    state, _, old = _status(path, current)
    if not force and state == "fresh" and old is not None:
        return path, old, False
    doc = signature_document(sdir, current)
    text = signature_text(doc)
    write_text_atomic(path, text)
    return path, json.loads(text), True


def load_session_signature(
    path: str | Path, committed: dict[str, str | None] | None = None
) -> Signature:
    """The :class:`Signature` of :func:`load_session_document`."""
    return signature_from_document(load_session_document(path, committed), str(Path(path)))


def load_session_document(
    path: str | Path, committed: dict[str, str | None] | None = None
) -> dict[str, Any]:
    """Read ``SESSION/signature.json`` (the checked document), refused unless it was built
    from the stage outputs committed in ``SESSION/stages`` (e.g. after a run killed between
    the two) and from the session's recording as it is now (e.g. after ``import --force``
    or a recording copied in, until ``identify`` succeeds on it).

    ``committed``: their content hashes when the caller has already checked the files
    (the stage runner, which has also hashed the recording); otherwise every stage file
    and the recording are read back and checked here."""
    p = Path(path)
    doc = read_signature_document(p)
    fix = f"run `pipeline identify {p.parent}`"
    checked_here = committed is None  # the runner has checked the recording itself
    recording = None
    outdated: list[tuple[str, Any, int]] = []
    if committed is None:
        recording, committed, outdated = recorded_committed_outdated(p.parent)
    if doc["provenance"]["stages"] != committed:
        raise ArmsigError(f"{p}: {STALE}", fix=fix)
    if outdated:  # an upgrade changed what a stage computes: its signature is not served
        name, old, new = outdated[0]
        raise ArmsigError(
            f"{p}: built by an older armsig (stage {name} version {old}, now {new}"
            + (f", and {len(outdated) - 1} more" if len(outdated) > 1 else "")
            + ")",
            expected="a signature of this armsig's stages",
            fix=fix,
        )
    built_from = doc["provenance"]["recording_sha256"]
    if checked_here and recording != built_from:
        raise ArmsigError(
            f"{p}: identified from another recording.mcap than the session's",
            expected=f"recording sha256 {built_from[:12]}…",
            got="no recording" if recording is None else f"sha256 {recording[:12]}…",
            fix=fix,
        )
    return doc
