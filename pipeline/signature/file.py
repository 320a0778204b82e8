"""The arm signature file ``signature.json`` (format in schemas/signature.md): its text,
reading and checking it, and the :class:`Signature` a controller drives with.

Pure of sessions: :mod:`pipeline.signature.session` writes a session's file from its
committed stages and refuses a stale one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.errors import ArmsigError
from pipeline.robots.description import RobotDescription, description_from_dict
from pipeline.signature.checks import DIGEST_KEY, check_document, document_digest, parse_json
from pipeline.signature.verdict import SignatureVerdict, verdict_of

if TYPE_CHECKING:  # the kinematics are imported where a signature is built or loaded
    from pipeline.kinematics.chain import SerialChain
    from pipeline.kinematics.nongeometric import NonGeometric

FILE_NAME = "signature.json"


def matrix_rows(T: np.ndarray) -> list[list[float]]:
    """A matrix as JSON-ready rows of Python floats."""
    return [[float(v) for v in row] for row in T]


def smodel_section(chain: SerialChain) -> dict[str, Any]:
    """The S-Model matrices (4.51) and parameters (4.52)-(4.57) of a signature chain."""
    from pipeline.kinematics.smodel import smodel_from_matrix

    sm = smodel_from_matrix(chain.links)
    return {
        "base": matrix_rows(chain.base),
        "links": [matrix_rows(B) for B in chain.links],
        "tool": matrix_rows(chain.tool),
        "parameters": [
            {
                "beta_deg": float(np.degrees(sm.beta[i])),
                "d_bar_cm": float(sm.d_bar[i]),
                "a_bar_cm": float(sm.a_bar[i]),
                "alpha_bar_deg": float(np.degrees(sm.alpha_bar[i])),
                "gamma_deg": float(np.degrees(sm.gamma[i])),
                "b_cm": float(sm.b[i]),
            }
            for i in range(chain.n_joints)
        ],
    }


def signature_text(doc: dict[str, Any]) -> str:
    """The file's text: ``doc`` with its ``sha256`` self-digest."""
    sealed = {**doc, DIGEST_KEY: document_digest(doc)}
    return json.dumps(sealed, indent=1, allow_nan=False) + "\n"


def read_signature_document(path: str | Path) -> dict[str, Any]:
    """Read and check a signature file (:func:`pipeline.signature.checks.check_document`)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ArmsigError(
            f"cannot read signature {p}",
            got=str(exc),
            fix="run `pipeline identify SESSION` to write it",
        ) from exc
    doc = parse_json(text, str(p))
    check_document(doc, str(p))
    return doc


@dataclass(frozen=True)
class Signature:
    """A loaded signature.

    ``chain``: the S-Model chain (sensor frame, encoder readings in rad / cm);
    ``robot``: the design robot description; ``sensor_from_design_base`` and
    ``design_flange_to_tool``: the design alignment X, Y (4, 4) of the file;
    ``verdict``: its verdict (None: the file has none); ``nongeometric``: where the
    joints sit for given readings, under gravity and with their angle errors (None: the
    rigid signature; :mod:`pipeline.kinematics.nongeometric`); ``camera``: a camera
    session's ``camera`` section (the set-up, the lens, the hand-eye transforms; None for
    other sensors).
    """

    robot: RobotDescription
    chain: SerialChain
    sensor_from_design_base: np.ndarray
    design_flange_to_tool: np.ndarray
    verdict: SignatureVerdict | None = None
    nongeometric: NonGeometric | None = None
    camera: dict[str, Any] | None = None  # a camera session's section (issue 39)

    @property
    def prismatic(self) -> np.ndarray:
        return self.robot.prismatic


def load_signature(path: str | Path) -> Signature:
    """Read a signature file; a one-line error for a missing, foreign, corrupt or
    inconsistent file (schemas/signature.schema.json and
    :func:`pipeline.signature.checks.check_document`)."""
    p = Path(path)
    return signature_from_document(read_signature_document(p), str(p))


def nongeometric_section(model: NonGeometric | None, sigma: np.ndarray) -> dict[str, Any]:
    """The file's ``nongeometric`` section: every term with its boundary unit, value and
    σ (``sigma`` internal units), and what the regressor is evaluated on."""
    from pipeline.kinematics.nongeometric import GRAVITY

    assert model is not None
    factor = np.where([u.startswith("rad") for u in model.terms.units], np.degrees(1.0), 1.0)
    units = ["deg" + u[3:] if u.startswith("rad") else u for u in model.terms.units]
    return {
        "regressor": "design chain (robot_description) at the readings",
        "gravity_in_design_base": [float(v) for v in GRAVITY],
        "measured_payloads_kg": list(model.measured_payloads_kg),
        "payload_kg": model.payload_kg,
        "terms": [
            {"name": n, "unit": u, "value": float(v), "sigma": float(e)}
            for n, u, v, e in zip(
                model.terms.names,
                units,
                model.coefficients * factor,
                sigma * factor,
                strict=True,
            )
        ],
    }


def nongeometric_from_section(section: dict[str, Any], design: SerialChain) -> NonGeometric:
    """The model of a ``nongeometric`` section (its ``terms``: name, boundary unit, value)
    whose levers are evaluated on ``design`` (the design chain, world: the design base)."""
    from pipeline.kinematics.nongeometric import NonGeometric, Terms

    rows = section["terms"]
    values = np.array([r["value"] for r in rows], float)
    values *= np.where([r["unit"].startswith("deg") for r in rows], np.radians(1.0), 1.0)
    terms = Terms.from_names([r["name"] for r in rows])
    measured = tuple(float(m) for m in section.get("measured_payloads_kg", ()))
    return NonGeometric(terms, values, design, float(section.get("payload_kg", 0.0)), measured)


def _nongeometric_of(doc: dict[str, Any], robot: RobotDescription) -> NonGeometric | None:
    section = doc.get("nongeometric")
    return nongeometric_from_section(section, robot.design_chain()) if section else None


def signature_from_document(doc: dict[str, Any], source: str) -> Signature:
    """The :class:`Signature` of a checked document."""
    from pipeline.kinematics.chain import SerialChain
    from pipeline.units import joints_to_internal

    robot = description_from_dict(doc["robot_description"], source=source)
    sm = doc["smodel"]
    al = doc["design_alignment"]
    chain = SerialChain(
        links=np.array(sm["links"], float),
        prismatic=robot.prismatic,
        base=np.array(sm["base"], float),
        tool=np.array(sm["tool"], float),
        joint_offsets=joints_to_internal(
            np.array(doc["signature_configuration"], float), robot.prismatic
        ),
    )
    return Signature(
        robot,
        chain,
        np.array(al["sensor_from_design_base"], float),
        np.array(al["design_flange_to_signature_tool"], float),
        verdict_of(doc),
        _nongeometric_of(doc, robot),
        doc.get("camera"),
    )
