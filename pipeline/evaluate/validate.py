"""``pipeline validate --against``: a session's signature against the rows of a second
foreign file (parsed in memory, never written into the session), as is and after
registering the base (:mod:`pipeline.evaluation.validation`), beside the design model
with its base and tool registered to the same points (the before of a before/after).

Every row of the file is a pose to check: a table or rct file needs no sweep structure
(its map's sweeps, if any, are not read). The file's target must be the session's tool
point, matched by id; another reflector is refused in one line.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import ArmsigError, os_errors_refused
from pipeline.evaluation.validation import error_distances, model_points, position_errors
from pipeline.importers import OS_FIX, parse_foreign
from pipeline.importers.mapping import ImportMap, load_map
from pipeline.importers.rows import refuse_absurd_coordinates
from pipeline.signature.file import FILE_NAME, Signature
from pipeline.signature.session import load_session_signature
from pipeline.units import joints_to_internal


def _as_poses(imap: ImportMap) -> ImportMap:
    """The map read as a plain list of poses: every row checked, no sweeps inferred."""
    return replace(imap, poses=True, check=None, select=(), sweep_column=None)


def _session_tool_target(sdir: Path) -> str | None:
    """The session's tool point id (``plan.tool_target``), None when it names none."""
    from pipeline.stages.runner import stage_path
    from pipeline.stages.session import session_plan
    from pipeline.stages.tables import read_table

    path = stage_path(sdir, "session")
    if not path.is_file():
        return None
    return session_plan(read_table(path)).get("tool_target") or None


def _target(file: str, ids: list[str], tool: str | None) -> str:
    """The file's target that is the session's tool point ``tool``; a file without it
    is refused in one line."""
    if tool is None or tool in ids:
        return tool or ids[0]
    raise ArmsigError(
        f"{file}: no target {tool!r}, the session's tool point",
        expected=f"the tool point's id {tool!r} among the file's targets",
        got=", ".join(repr(t) for t in ids),
        fix=f'name its [[targets]] id "{tool}" in the map, if it is that reflector',
    )


def design_errors(sig: Signature, q: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Each measured point's distance (m,) cm from the design model with its base and tool
    point registered to the points (:func:`pipeline.refine.baseline.register_design`: the
    before of a before/after, what the robot does uncalibrated in a registered cell)."""
    from pipeline.refine.baseline import register_design
    from pipeline.units import joints_to_internal

    qi = joints_to_internal(q, sig.prismatic)
    tool = sig.design_flange_to_tool[:3, 3]  # a start: the tool point is re-solved
    return register_design(sig.robot.design_chain(), qi, measured, tool).errors_cm


def validate_against(
    session_dir: str | Path, path: str | Path, fmt: str, map_path: str | Path | None = None
) -> dict[str, Any]:
    """The signature of ``session_dir`` against every row of a second foreign file
    (parsed in memory, never written into the session): its target of the session's
    tool point's id vs the model, and the registered design model beside it."""
    sdir = Path(session_dir)
    with os_errors_refused(path, OS_FIX):
        sig = load_session_signature(sdir / FILE_NAME)
        imap = ImportMap() if map_path is None else load_map(Path(map_path))
        if fmt != "sscanss2":
            imap = _as_poses(imap)
        rows, _ = parse_foreign(Path(path), fmt, sig.robot, imap)
        refuse_absurd_coordinates(rows)
        target = _target(Path(path).name, list(rows.targets), _session_tool_target(sdir))
    measured = rows.targets[target]
    ok = np.isfinite(rows.q).all(axis=1) & np.isfinite(measured).all(axis=1)
    if not ok.any():
        raise ArmsigError(f"{Path(path).name}: no row with finite readings and coordinates")
    q = sig.robot.joints_from_readings(rows.q[ok])
    model = model_points(sig.chain, q, sig.prismatic, sig.nongeometric)
    raw, reg = error_distances(model, measured[ok])
    design = position_errors(design_errors(sig, q, measured[ok]), None)
    predicted = _predicted_rms_cm(sdir, joints_to_internal(q, sig.prismatic))
    return {
        "session": str(sdir),
        "file": Path(path).name,
        "format": fmt,
        "target": target,
        "rows_skipped": int((~ok).sum()),
        **position_errors(raw, reg).to_dict(),
        "design_registered_mean_cm": design.mean_cm,
        "design_registered_rms_cm": design.rms_cm,
        "design_registered_max_cm": design.max_cm,
        "predicted_rms_cm": predicted,
        "gain_registered": None if reg is None else _gain(design, reg),
    }


def _gain(design: Any, registered: np.ndarray) -> float | None:
    """The registered design's RMS over the signature's (base registered), same points."""
    rms = float(np.sqrt(np.mean(registered**2)))
    return None if design.rms_cm is None or not rms > 0 else design.rms_cm / rms


def _predicted_rms_cm(sdir: Path, q: np.ndarray) -> float | None:
    """The session's predicted RMS tool error at these configurations (rad, cm): its
    parameters' part there and its unmodelled part (issue 41,
    :func:`pipeline.stages.uncertainty.predicted_at`); None when the session has no
    prediction (refinement disabled, or stages from before it)."""
    from pipeline.stages.runner import stage_path
    from pipeline.stages.tables import read_table
    from pipeline.stages.uncertainty import predicted_at

    names = ("session", "refine", "frames", "uncertainty")
    paths = {n: stage_path(sdir, n) for n in names}
    if not all(p.is_file() for p in paths.values()):
        return None
    tables = {n: read_table(p) for n, p in paths.items()}
    if "sigma_unmodelled_cm" not in tables["uncertainty"].column_names:
        return None
    pred = predicted_at(tables, q)
    return None if pred is None else float(np.sqrt(np.mean(pred**2)))
