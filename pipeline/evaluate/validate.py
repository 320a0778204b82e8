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
from pipeline.evaluation.validation import (
    error_distances,
    joints_sitting,
    model_points,
    position_errors,
)
from pipeline.importers import OS_FIX, expand_paths, parse_foreign
from pipeline.importers.mapping import ImportMap, load_map
from pipeline.importers.rows import refuse_absurd_coordinates
from pipeline.signature.file import FILE_NAME, Signature
from pipeline.signature.session import load_session_signature
from pipeline.units import joints_to_internal

#: ``--tool-point registered``: the validation file's point located by its own fit.
REGISTERED = "registered"


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
    session_dir: str | Path,
    path: str | Path | list[str | Path],
    fmt: str,
    map_path: str | Path | None = None,
    strict: bool = False,
    tool_point: str | None = None,
) -> dict[str, Any]:
    """The signature of ``session_dir`` against every row of a second data set (one or
    several foreign files, paths or globs, in order; parsed in memory, never written into
    the session): its target of the session's tool point's id vs the model, and the
    registered design model beside it.

    ``tool_point = "registered"``: the file measured another point on the tool, one the
    session never measured (its map's ``tool_target``, else its first target). Its place
    on the last link is fitted with the base to the file's own points (the signature's
    chain, :func:`pipeline.refine.baseline.register_design`: 9 parameters, as the design
    model beside it), and the errors are those of that fit, said in ``tool_point``.

    ``tool_point = ID``: the file's target ID, measured at the configuration of the map's
    ``tool_point_q`` (readings): the rows at it locate the point on the last link through
    the signature (:func:`_located_tool`), the other rows are judged with it."""
    sdir = Path(session_dir)
    specs = path if isinstance(path, list) else [path]
    with os_errors_refused(specs[0], OS_FIX):
        files = expand_paths(specs)
        sig = load_session_signature(sdir / FILE_NAME)
        imap = ImportMap() if map_path is None else load_map(Path(map_path))
        imap = replace(imap, strict=strict)
        if fmt != "sscanss2":
            imap = _as_poses(imap)
        rows, _ = parse_foreign(files, fmt, sig.robot, imap)
        refuse_absurd_coordinates(rows)
        if tool_point == REGISTERED:
            target = imap.tool_target or next(iter(rows.targets))
        elif tool_point is not None:
            target = _known_point(rows.name, list(rows.targets), tool_point, imap)
        else:
            target = _target(rows.name, list(rows.targets), _session_tool_target(sdir))
    measured = rows.targets[target]
    ok = np.isfinite(rows.q).all(axis=1) & np.isfinite(measured).all(axis=1)
    if not ok.any():
        raise ArmsigError(f"{rows.name}: no row with finite readings and coordinates")
    q, points = sig.robot.joints_from_readings(rows.q[ok]), measured[ok]
    kg = None if rows.payload_kg is None else rows.payload_kg[ok]
    if kg is not None and sig.nongeometric is not None:
        for m in np.unique(kg[np.isfinite(kg)]):
            sig.nongeometric.with_payload(float(m))  # a payload it cannot predict: refused
    located, chain, at_rows = None, sig.chain, 0
    if tool_point not in (None, REGISTERED):  # located at a known configuration
        at = _at_configuration(rows.name, rows.q[ok], imap.tool_point_q, sig.robot)
        located, chain = _located_tool(sig, q[at], points[at], None if kg is None else kg[at])
        at_rows, q, points = int(at.sum()), q[~at], points[~at]
        kg = None if kg is None else kg[~at]
        if len(q) == 0:
            raise ArmsigError(
                f"{rows.name}: every row is at tool_point_q",
                expected="other rows to judge besides those that locate the tool point",
                fix="add the rows to validate, or correct tool_point_q in the map",
            )
    if tool_point == REGISTERED:
        raw, located = _registered_tool(sig, q, points, kg)
        reg: np.ndarray | None = raw
    else:
        model = model_points(chain, q, sig.prismatic, sig.nongeometric, kg)
        raw, reg = error_distances(model, points)
    design = position_errors(design_errors(sig, q, points), None)
    predicted = _predicted_rms_cm(sdir, joints_to_internal(q, sig.prismatic))
    return {
        "session": str(sdir),
        "file": files[0].name if len(files) == 1 else rows.name,
        "files": [f.name for f in files],
        "format": fmt,
        "target": target,
        "rows_skipped": int((~ok).sum()) + rows.dropped,
        "tool_point_rows": at_rows,
        "notes": list(rows.notes),
        **position_errors(raw, reg).to_dict(),
        "design_registered_mean_cm": design.mean_cm,
        "design_registered_rms_cm": design.rms_cm,
        "design_registered_max_cm": design.max_cm,
        "predicted_rms_cm": predicted,
        "gain_registered": None if reg is None else _gain(design, reg),
        "tool_point": "session" if located is None else (tool_point or REGISTERED),
        "tool_point_local_cm": None if located is None else [float(v) for v in located],
        "tool_point_offset_cm": None
        if located is None
        else float(np.linalg.norm(located - sig.chain.tool[:3, 3])),
    }


def _known_point(name: str, ids: list[str], tool_point: str, imap: ImportMap) -> str:
    """The target ``tool_point`` of the file, located at the map's ``tool_point_q``."""
    if tool_point not in ids:
        raise ArmsigError(
            f"{name}: --tool-point {tool_point!r} is no target of the file",
            expected=f"{REGISTERED!r}, or one of the file's targets: " + ", ".join(ids),
            fix="name a [[targets]] id of the map, or --tool-point registered",
        )
    if imap.tool_point_q is None:
        raise ArmsigError(
            f"{imap.name}: --tool-point {tool_point} needs tool_point_q in the map",
            expected="tool_point_q = [...]: the readings (deg / cm) at which the file measured "
            f"{tool_point} to locate it",
            fix="add tool_point_q to the map, or --tool-point registered",
        )
    return tool_point


def _at_configuration(
    name: str, readings: np.ndarray, q0: tuple[float, ...] | None, robot: Any
) -> np.ndarray:
    """The rows (bool) whose readings are ``q0`` (within each joint's encoder resolution);
    none is refused in one line."""
    assert q0 is not None  # _known_point: the map has it
    if len(q0) != robot.n_joints:
        raise ArmsigError(
            f"tool_point_q has {len(q0)} values",
            expected=f"{robot.n_joints}, one reading per joint (deg / cm)",
            fix="list one reading per joint of the robot in the map",
        )
    at = (np.abs(readings - np.array(q0)) <= robot.encoder_resolution).all(axis=1)
    if not at.any():
        raise ArmsigError(
            f"{name}: no row at tool_point_q {list(q0)}",
            expected="a row whose readings are the map's tool_point_q (within the encoder "
            "resolution)",
            fix="correct tool_point_q, or measure the point at it",
        )
    return at


def _located_tool(
    sig: Signature, q: np.ndarray, measured: np.ndarray, kg: np.ndarray | None
) -> tuple[Any, Any]:
    """The tool point (3,) in the last link's frame (cm) from its measurements ``measured``
    (m, 3) at joint values ``q`` (deg / cm) under payloads ``kg`` through the signature (the
    mean of ``F(q)⁻¹ p``), and the signature's chain with that tool point."""
    from dataclasses import replace as with_fields

    from pipeline.kinematics.chain import forward_kinematics
    from pipeline.kinematics.transforms import trans

    qi = joints_sitting(q, sig.prismatic, sig.nongeometric, kg)
    F = forward_kinematics(with_fields(sig.chain, tool=np.eye(4)), qi)
    local = np.einsum("kji,kj->ki", F[:, :3, :3], measured - F[:, :3, 3]).mean(axis=0)
    return local, with_fields(sig.chain, tool=trans(*local))


def _registered_tool(
    sig: Signature, q: np.ndarray, measured: np.ndarray, kg: np.ndarray | None
) -> tuple[Any, Any]:
    """The signature's chain with its base and a tool point fitted to ``measured`` (m, 3)
    at joint values ``q`` (deg / cm) under payloads ``kg``: each point's distance (m,) cm
    and the point (3,) in the last link's frame (cm)."""
    from pipeline.refine.baseline import register_design

    qi = joints_sitting(q, sig.prismatic, sig.nongeometric, kg)
    fit = register_design(sig.chain, qi, measured, sig.design_flange_to_tool[:3, 3])
    return fit.errors_cm, fit.tool


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
