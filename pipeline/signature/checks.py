"""Checks of a ``signature.json`` document: JSON parsing, schemas/signature.schema.json,
the self-digest, and what a schema cannot say (per-joint lengths, rigid matrices,
the robot description). Each failure is one line naming the file and the field."""

from __future__ import annotations

import hashlib
import json
from typing import Any

import fastjsonschema
import numpy as np

from pipeline.errors import ArmsigError
from pipeline.robots.description import description_from_dict
from pipeline.schemas import compiled_validator, strict_json

FORMAT = "armsig.signature"
#: 4: the ``sha256`` self-digest; 3: the design alignment stays put along symmetries of the
#: design model (:mod:`pipeline.kinematics.alignment`). Other versions are refused on read
#: and rewritten by ``pipeline identify``.
FORMAT_VERSION = 4
SCHEMA_FILE = "signature.schema.json"
DIGEST_KEY = "sha256"
#: Rigid matrices: max |RᵀR − I| and |last row − [0 0 0 1]|. The writer's products of
#: rotations are orthonormal to ~2e-15 (measured on robot1-7); 1e-9 leaves six orders of
#: margin and still catches an edited rotation entry.
RIGID_TOL = 1e-9
REFIX = "re-run `pipeline identify` on its session"


def parse_json(text: str, source: str) -> Any:
    """Parse JSON, refusing NaN, Infinity and numbers that overflow to infinity."""
    try:
        return strict_json(text, finite=True)
    except ValueError as exc:  # JSONDecodeError too
        raise ArmsigError(f"{source}: not valid JSON", got=str(exc), fix=REFIX) from exc


def document_digest(doc: dict[str, Any]) -> str:
    """SHA-256 of the canonical JSON of ``doc`` without its digest key."""
    body = {k: v for k, v in doc.items() if k != DIGEST_KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def check_document(doc: Any, source: str) -> None:
    """Check a parsed signature document.

    Raises
    ------
    ArmsigError
        One line: what is wrong, what was expected, what to try.
    """
    if not isinstance(doc, dict):
        raise ArmsigError(
            f"{source}: not an armsig signature",
            expected="a JSON object",
            got=type(doc).__name__ if doc is not None else "null",
            fix=REFIX,
        )
    if doc.get("format") != FORMAT:
        raise ArmsigError(
            f"{source}: not an armsig signature", expected=FORMAT, got=repr(doc.get("format"))
        )
    if doc.get("format_version") != FORMAT_VERSION:
        raise ArmsigError(
            f"{source}: unsupported signature format_version",
            expected=str(FORMAT_VERSION),
            got=repr(doc.get("format_version")),
            fix=REFIX + " with this armsig",
        )
    try:
        compiled_validator(SCHEMA_FILE, detailed=False)(doc)
    except fastjsonschema.JsonSchemaValueException as exc:
        raise ArmsigError(
            f"{source}: signature does not match {SCHEMA_FILE}",
            got=exc.message.replace("data.", "", 1).replace("data ", "document ", 1),
            fix=REFIX,
        ) from exc
    if doc[DIGEST_KEY] != document_digest(doc):
        raise ArmsigError(
            f"{source}: signature content differs from its sha256 (edited or corrupt)",
            fix=REFIX,
        )
    _check_numbers(doc, source)


def _check_numbers(doc: dict[str, Any], source: str) -> None:
    n = len(doc["joint_names"])
    per_joint = {
        "joint_types": doc["joint_types"],
        "joint_limits": doc["joint_limits"],
        "encoder_resolution": doc["encoder_resolution"],
        "signature_configuration": doc["signature_configuration"],
        "smodel.links": doc["smodel"]["links"],
        "smodel.parameters": doc["smodel"]["parameters"],
        "pseudo_dh": doc["pseudo_dh"],
    }
    for key, values in per_joint.items():
        if len(values) != n:
            raise ArmsigError(
                f"{source}: {key} has {len(values)} entries",
                expected=f"one per joint ({n})",
                fix=REFIX,
            )
    matrices = {
        "smodel.base": doc["smodel"]["base"],
        "smodel.tool": doc["smodel"]["tool"],
        "pseudo_dh_base": doc["pseudo_dh_base"],
        "pseudo_dh_tool": doc["pseudo_dh_tool"],
        **{
            f"design_alignment.{k}": doc["design_alignment"][k]
            for k in ("sensor_from_design_base", "design_flange_to_signature_tool")
        },
        **{f"smodel.links[{i}]": B for i, B in enumerate(doc["smodel"]["links"])},
    }
    for k, T in doc.get("camera", {}).items():  # a camera's hand-eye transforms (issue 39)
        if k.endswith(("_in_base", "_in_flange")):
            matrices[f"camera.{k}"] = T
    if "thesis_smodel" in doc:  # files of the refinement (issue 15)
        th = doc["thesis_smodel"]
        matrices["thesis_smodel.base"], matrices["thesis_smodel.tool"] = th["base"], th["tool"]
        matrices.update({f"thesis_smodel.links[{i}]": B for i, B in enumerate(th["links"])})
    for key, value in matrices.items():
        _check_rigid(np.array(value, float), f"{source}: {key}")
    _check_robot(doc, source)
    for i, (row, kind) in enumerate(zip(doc["pseudo_dh"], doc["joint_types"], strict=True)):
        if row["type"] != kind:
            raise ArmsigError(
                f"{source}: pseudo_dh[{i}] is {row['type']}", expected=kind, fix=REFIX
            )


def _check_rigid(T: np.ndarray, where: str) -> None:
    R = T[:3, :3]
    ortho = float(np.abs(R.T @ R - np.eye(3)).max())
    last = float(np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max())
    if ortho > RIGID_TOL or last > RIGID_TOL or np.linalg.det(R) < 0:
        raise ArmsigError(
            f"{where} is not a rigid transform",
            expected=f"orthonormal rotation with det +1 and last row [0 0 0 1] (to {RIGID_TOL:g})",
            got=f"max |RᵀR − I| {ortho:.1e}, last row {T[3].tolist()}",
            fix=REFIX,
        )


def _check_robot(doc: dict[str, Any], source: str) -> None:
    robot = description_from_dict(doc["robot_description"], source=f"{source}: robot_description")
    listed = (
        doc["robot"],
        doc["joint_names"],
        doc["joint_types"],
        [[float(v) for v in lim] for lim in doc["joint_limits"]],
        [float(v) for v in doc["encoder_resolution"]],
    )
    described = (
        robot.name,
        [j.name for j in robot.joints],
        [j.type for j in robot.joints],
        robot.limits.tolist(),
        robot.encoder_resolution.tolist(),
    )
    names = ("robot", "joint_names", "joint_types", "joint_limits", "encoder_resolution")
    for name, a, b in zip(names, listed, described, strict=True):
        if a != b:
            raise ArmsigError(
                f"{source}: {name} does not match robot_description",
                expected=repr(b),
                got=repr(a),
                fix=REFIX,
            )
