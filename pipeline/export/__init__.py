"""Exports of a session's signature (or its design model): URDF, D-H, modified D-H, JSON.

``export(session_dir, fmt)`` reads the session's signature only if it matches the
session's stages, builds the exported model, checks that the numbers as written reproduce
the chain's forward kinematics at :data:`CHECK_CONFIGURATIONS` random configurations within
the joint limits (to :data:`CHECK_POSITION_M`, :data:`CHECK_ORIENTATION_RAD`) and only then
writes the file atomically. Every format holds the rigid chain only: a signature's
non-geometric terms go beside it (:mod:`pipeline.export.sidecar`). Formats and frames:
docs/export.md.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import check_new_file, check_writable, write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.export.dh_table import (
    DHTable,
    ModifiedDHTable,
    chain_from_dh_table,
    chain_from_modified,
    dh_table_from_chain,
    modified_from_dh,
)
from pipeline.export.documents import chain_document, chain_from_document, dh_document, mdh_document
from pipeline.export.sidecar import check_sidecar, sidecar_document, sidecar_path
from pipeline.export.urdf import M_PER_CM, chain_from_origins, urdf_text, written_origins
from pipeline.kinematics.chain import SerialChain, forward_kinematics, in_frame
from pipeline.kinematics.transforms import invert_transform, pose_error
from pipeline.signature.alignment import FRAMES
from pipeline.signature.file import FILE_NAME, Signature, signature_from_document
from pipeline.signature.session import load_session_document
from pipeline.signature.verdict import verdict_gate
from pipeline.units import joints_to_internal

FORMATS = ("urdf", "dh", "mdh", "json")
EXPORT_DIR = "export"
_SUFFIX = {"urdf": ".urdf", "dh": ".dh.json", "mdh": ".mdh.json", "json": ".chain.json"}
#: What the warning calls each format: all four hold the rigid chain only.
_NAME = {"urdf": "URDF", "dh": "D-H table", "mdh": "modified D-H table", "json": "chain JSON"}

#: The acceptance of issue 16: the export reproduces armsig's FK to 1e-9 m and 1e-9 rad
#: (round-off of the chain products is ~1e-15 m; a wrong convention is ≥ 1e-3 m).
CHECK_POSITION_M = 1e-9
CHECK_ORIENTATION_RAD = 1e-9
CHECK_CONFIGURATIONS = 1000


@dataclass(frozen=True)
class ExportResult:
    """What was written and how closely it reproduces the chain it came from."""

    path: str
    format: str
    model: str
    frame: str
    configurations: int
    max_position_error_m: float
    max_orientation_error_rad: float
    verdict: str | None = None  # the signature's verdict (None: it has none)
    verdict_warning: str | None = None  # a CHECK, or a FAIL accepted (accept_verdict)
    sidecar: str | None = None  # the signature's non-geometric terms, beside the file
    sidecar_warning: str | None = None  # that the file holds the rigid chain only

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def export_chain(sig: Signature, design: bool, frame: str) -> SerialChain:
    """The signature's chain (or the design model's) with its world in ``frame``: the sensor
    frame, or the design base placed by the signature's design alignment."""
    X = sig.sensor_from_design_base  # design base in the sensor frame
    if design:
        chain = sig.robot.design_chain()  # world: the design base
        return chain if frame == "design-base" else in_frame(chain, invert_transform(X))
    return sig.chain if frame == "sensor" else in_frame(sig.chain, X)


def random_readings(sig: Signature, m: int, seed: int = 0) -> np.ndarray:
    """``m`` uniform encoder readings within the joint limits (rad / cm), shape (m, n)."""
    lim = sig.robot.limits
    rng = np.random.default_rng(seed)
    return joints_to_internal(rng.uniform(lim[:, 0], lim[:, 1], (m, len(lim))), sig.prismatic)


def _check(chain: SerialChain, exported: SerialChain, q: np.ndarray) -> tuple[float, float]:
    dp, dr = pose_error(forward_kinematics(chain, q), forward_kinematics(exported, q))
    pos, rot = float(dp.max()) * M_PER_CM, float(dr.max())
    if not (pos <= CHECK_POSITION_M and rot <= CHECK_ORIENTATION_RAD):
        raise RuntimeError(  # a bug in armsig, never a user's file: exit 70
            f"the export does not reproduce the chain: {pos:.3e} m, {rot:.3e} rad"
        )
    return pos, rot


def _column(doc: dict[str, Any], key: str) -> np.ndarray:
    """A column of a table document in math units (``_deg`` keys to radians)."""
    v = np.array([row[key] for row in doc["rows"]], float)
    return np.radians(v) if key.endswith("_deg") else v


def _dh_from_document(doc: dict[str, Any], pris: np.ndarray) -> DHTable:
    th, d, a, al, be = (
        _column(doc, k) for k in ("theta_deg", "d_cm", "a_cm", "alpha_deg", "beta_deg")
    )
    return DHTable(th, d, a, al, be, pris, np.array(doc["base"]), np.array(doc["tool"]))


def _mdh_from_document(doc: dict[str, Any], pris: np.ndarray) -> ModifiedDHTable:
    keys = ("alpha_prev_deg", "a_prev_cm", "beta_prev_deg", "theta_deg", "d_cm")
    al, a, be, th, d = (_column(doc, k) for k in keys)
    return ModifiedDHTable(al, a, be, th, d, pris, np.array(doc["base"]), np.array(doc["tool"]))


def json_text(doc: dict[str, Any]) -> str:
    """``doc`` as JSON, one top-level key per line and one line per list item (a table row,
    a matrix)."""

    def value(v: Any) -> str:
        if isinstance(v, list) and v and isinstance(v[0], dict | list):
            items = ",\n".join(f"  {json.dumps(x, allow_nan=False)}" for x in v)
            return f"[\n{items}\n ]"
        return json.dumps(v, allow_nan=False)

    body = ",\n".join(f" {json.dumps(k)}: {value(v)}" for k, v in doc.items())
    return "{\n" + body + "\n}\n"


def render(
    sig: Signature, chain: SerialChain, fmt: str, model: str, frame: str
) -> tuple[str, SerialChain]:
    """The file's text and the chain its numbers (as written) describe."""
    robot, pris = sig.robot, sig.prismatic
    if fmt == "urdf":
        where = "sensor frame" if frame == "sensor" else "design base frame"
        comment = (
            f"armsig {model} model of {robot.name}, base_link = the {where}; SI units; "
            "joint variable = encoder reading (rad, m), encoder offsets in the joint origins"
        )
        name = robot.name if model == "signature" else f"{robot.name}_design"
        return urdf_text(chain, robot, name, comment), chain_from_origins(
            written_origins(chain), pris
        )
    if fmt == "json":
        doc = chain_document(chain, robot, model, frame)
        text = json_text(doc)
        return text, chain_from_document(json.loads(text), pris)
    table = dh_table_from_chain(chain)
    if fmt == "dh":
        doc = dh_document(table, robot, model, frame)
        text = json_text(doc)
        return text, chain_from_dh_table(_dh_from_document(json.loads(text), pris))
    doc = mdh_document(modified_from_dh(table), table.hayati, robot, model, frame)
    text = json_text(doc)
    return text, chain_from_modified(_mdh_from_document(json.loads(text), pris))


def default_path(session_dir: Path, fmt: str, design: bool, frame: str) -> Path:
    """``SESSION/export/{signature|design}[.design-base].{urdf,dh.json,mdh.json,chain.json}``."""
    stem = ("design" if design else "signature") + ("" if frame == "sensor" else f".{frame}")
    return session_dir / EXPORT_DIR / (stem + _SUFFIX[fmt])


def export(
    session_dir: str | Path,
    fmt: str,
    out: str | Path | None = None,
    design: bool = False,
    frame: str = "sensor",
    force: bool = False,
    accept_verdict: bool = False,
) -> ExportResult:
    """Export a session's signature (``design``: its design model) as ``fmt``.

    ``out`` defaults to :func:`default_path` (armsig's own folder, rewritten every time);
    an ``out`` that exists is refused unless ``force``. A signature whose verdict is FAIL
    is refused unless ``accept_verdict`` (:func:`pipeline.signature.verdict.verdict_gate`).
    A signature with non-geometric terms also gets the sidecar of
    :func:`pipeline.export.sidecar.sidecar_path` (checked, and refused like ``out``), and
    the result says so in ``sidecar_warning``; a rigid one is exported as before (and its
    default folder loses a stale sidecar).
    """
    if fmt not in FORMATS:
        raise ArmsigError(f"unknown export format {fmt!r}", expected=", ".join(FORMATS))
    if frame not in FRAMES:
        raise ArmsigError(f"unknown export frame {frame!r}", expected=", ".join(FRAMES))
    sdir = Path(session_dir)
    if out is None:
        path = default_path(sdir, fmt, design, frame)
        check_writable(path.parent, "export folder", folder=True)
    else:
        path = check_new_file(out, "--out", force)
    doc = load_session_document(sdir / FILE_NAME)
    sig = signature_from_document(doc, str(sdir / FILE_NAME))
    warning = verdict_gate(sig.verdict, str(sdir), accept_verdict)
    section = None if design else doc.get("nongeometric")  # the design model is rigid
    side = sidecar_path(path)
    if section and out is not None:  # armsig's own folder is rewritten, a user's file is not
        check_new_file(side, "sidecar", force)
    model = "design" if design else "signature"
    chain = export_chain(sig, design, frame)
    text, written = render(sig, chain, fmt, model, frame)
    q = random_readings(sig, CHECK_CONFIGURATIONS)
    pos, rot = _check(chain, written, q)
    side_warning = None
    if section:  # the terms first: the export never stands without them
        side_text = json_text(sidecar_document(sig, section, path.name))
        check_sidecar(json.loads(side_text), sig, q)
        write_text_atomic(side, side_text)
        side_warning = _sidecar_warning(fmt, len(section["terms"]), side)
    elif out is None:  # no stale terms beside a rigid export in armsig's own folder
        side.unlink(missing_ok=True)
    write_text_atomic(path, text)
    status = None if sig.verdict is None else sig.verdict.status
    return ExportResult(
        str(path), fmt, model, frame, CHECK_CONFIGURATIONS, pos, rot, status, warning,
        str(side) if section else None, side_warning,
    )  # fmt: skip


def _sidecar_warning(fmt: str, n: int, side: Path) -> str:
    terms = "1 non-geometric term is" if n == 1 else f"{n} non-geometric terms are"
    return (
        f"the {_NAME[fmt]} holds the rigid chain only; the signature's {terms} written "
        f"beside it in {side}"
    )
