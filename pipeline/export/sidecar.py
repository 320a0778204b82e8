"""The whole signature beside an export that holds a rigid chain (issues 27, 43).

URDF, the D-H tables and the chain JSON state a rigid ``T(q)``; a signature with a
``nongeometric`` section puts the joints at ``q + Φ(q) β`` first
(:mod:`pipeline.kinematics.nongeometric`), and the file holds the rigid chain nearest
that (:mod:`pipeline.export.rigid`). The sidecar ``<export>.nongeometric.json``
(:func:`sidecar_path`) holds the whole signature: the terms as signature.json states them
(name, boundary unit, value, σ), the equation, the design chain whose levers ``Φ`` is
evaluated on, the signature's own rigid chain the terms go with (in the export's world
frame) and what the file loses against it. Format in docs/export.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.export.documents import chain_document, chain_from_document
from pipeline.export.rigid import RigidLoss
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.nongeometric import NonGeometric, Terms
from pipeline.kinematics.transforms import pose_error
from pipeline.robots.description import RobotDescription
from pipeline.signature.file import Signature, nongeometric_from_section

SUFFIX = ".nongeometric.json"
#: The sidecar's terms as written reproduce the signature's joint values ``q + Δ(q)`` to
#: this (rad / cm): the degree round trip of a value costs ~1e-16 of it, and joint values
#: of a few rad (a few hundred cm) ~1e-14; a term in the wrong unit misses by its Δ × 56.
CHECK_JOINT = 1e-12
CONVENTION = (
    "a reading q (deg / cm; the URDF's rad / m converted) puts joint j at "
    "q_j + sum of value * Phi(q) over the terms of joint j; the whole signature is the "
    "rigid chain signature_* below (signature_convention, world: the export's frame "
    "signature_frame) evaluated there, T_s(q + Delta(q)). The file beside holds another "
    "rigid chain, the one nearest the whole signature (rigid_loss: what it loses at the "
    "tool point); do not apply the terms to it. compliance.j<j>.link<k> (deg/cm): "
    "Phi = h_jk(q) = z_{j-1} . ((o_k - o_{j-1}) x g) (cm), the lever about joint j's axis "
    "of a unit weight at the origin of link k's frame, with z_i, o_i the z axis and origin "
    "of frame F_i = design_base K_1 ... K_i of the design chain below at the reading q "
    "(design_convention; the design base frame) and g = gravity_in_design_base. "
    "harmonic.j<j>.cos|sin (deg): Phi = cos|sin(q_j)"
)
#: The chains' keys in the sidecar: ``design_`` or ``signature_`` + the chain document's key.
_DESIGN_KEYS = ("joint_offsets", "base", "links", "tool")
#: The sidecar's signature chain at the terms' joint values reproduces the signature's
#: tool pose to this (cm; 1e-9 m, the export's own check): JSON keeps every double.
CHECK_POSITION_CM = 1e-7


def sidecar_path(export_path: Path) -> Path:
    """``signature.urdf`` → ``signature.nongeometric.json``, ``t.dh.json`` →
    ``t.dh.nongeometric.json``: the export's last suffix replaced."""
    return export_path.with_suffix(SUFFIX)


def _term(robot: RobotDescription, row: dict[str, Any]) -> dict[str, Any]:
    """A row of signature.json's ``nongeometric.terms`` with its joint's name and its
    equation, ``q_j += value * Phi(q)``."""
    terms = Terms.from_names([row["name"]])
    if terms.compliance:
        j, k = terms.compliance[0]
        equation = f"q_{j} (deg) += value (deg/cm) * h_{j},{k}(q) (cm)"
    elif terms.payload:
        j, n = terms.payload[0], robot.n_joints
        equation = f"q_{j} (deg) += value (deg/kg/cm) * payload_kg * h_{j},{n}(q) (cm)"
    else:
        j, f = terms.harmonic[0]
        equation = f"q_{j} (deg) += value (deg) * {f}(q_{j})"
    return {"name": row["name"], "joint": robot.joints[j - 1].name, "unit": row["unit"],
            "value": row["value"], "sigma": row["sigma"], "equation": equation}  # fmt: skip


def sidecar_document(
    sig: Signature,
    section: dict[str, Any],
    beside: str,
    full: SerialChain,
    frame: str,
    loss: RigidLoss,
) -> dict[str, Any]:
    """The sidecar of the export ``beside`` (its file name): the terms of signature.json's
    ``section`` (name, unit, value, σ as written there), each with its joint and
    equation, the design chain (cm, deg) whose levers they multiply, the signature's
    rigid chain ``full`` the terms go with (world: the export's ``frame``) and the
    file's ``loss``."""
    robot = sig.robot
    design = chain_document(robot.design_chain(), robot, "design", "design-base")
    own = chain_document(full, robot, "signature", frame)
    return {
        "format": "armsig-nongeometric",
        "robot": robot.name,
        "beside": beside,
        "length_unit": "cm",
        "angle_unit": "deg",
        "convention": CONVENTION,
        "gravity_in_design_base": section["gravity_in_design_base"],
        "measured_payloads_kg": section["measured_payloads_kg"],
        "payload_kg": section["payload_kg"],
        "terms": [_term(robot, row) for row in section["terms"]],
        "design_convention": design["convention"],
        "joints": design["joints"],
        **{f"design_{k}": design[k] for k in _DESIGN_KEYS},
        "signature_frame": frame,
        "signature_convention": own["convention"],
        **{f"signature_{k}": own[k] for k in _DESIGN_KEYS},
        "rigid_loss": {k: v for k, v in loss.to_dict().items() if k != "held"},
        "rigid_held": list(loss.held),
    }


def nongeometric_from_sidecar(doc: dict[str, Any], prismatic: np.ndarray) -> NonGeometric:
    """The model a sidecar (as read back) states, on its own design chain."""
    design = chain_from_document({k: doc[f"design_{k}"] for k in _DESIGN_KEYS}, prismatic)
    return nongeometric_from_section(doc, design)


def signature_from_sidecar(doc: dict[str, Any], prismatic: np.ndarray) -> SerialChain:
    """The signature's rigid chain a sidecar (as read back) states (world: its
    ``signature_frame``)."""
    return chain_from_document({k: doc[f"signature_{k}"] for k in _DESIGN_KEYS}, prismatic)


def check_sidecar(doc: dict[str, Any], sig: Signature, q: np.ndarray, full: SerialChain) -> float:
    """The largest difference (rad / cm) between the joint values the sidecar ``doc`` (as
    read back) and the signature give readings ``q`` (m, n); an internal error above
    :data:`CHECK_JOINT`, or when the sidecar's chain there misses the signature's tool
    pose (``full``, the export's frame) by :data:`CHECK_POSITION_CM`."""
    assert sig.nongeometric is not None
    mine = nongeometric_from_sidecar(doc, sig.prismatic).effective(q)
    want = sig.nongeometric.effective(q)
    err = float(np.abs(mine - want).max())
    chain = signature_from_sidecar(doc, sig.prismatic)
    dp, dr = pose_error(forward_kinematics(chain, mine), forward_kinematics(full, want))
    if not (err <= CHECK_JOINT and dp.max() <= CHECK_POSITION_CM and dr.max() <= CHECK_JOINT):
        raise RuntimeError(  # a bug in armsig, never a user's file: exit 70
            f"the non-geometric sidecar does not reproduce the signature: {err:.3e}, "
            f"{dp.max():.3e} cm"
        )
    return err
