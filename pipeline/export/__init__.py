"""Exports of a session's signature (or its design model): URDF, D-H, modified D-H, JSON.

``export(session_dir, fmt)`` reads the session's signature only if it matches the
session's stages, builds the exported model, checks that the numbers as written reproduce
the chain's forward kinematics at :data:`CHECK_CONFIGURATIONS` random configurations within
the joint limits (to :data:`CHECK_POSITION_M`, :data:`CHECK_ORIENTATION_RAD`) and only then
writes the file atomically. Every format holds a rigid chain: for a signature with
non-geometric terms the one nearest the whole signature (:mod:`pipeline.export.rigid`,
its loss stated), the whole signature beside it (:mod:`pipeline.export.sidecar`).
Formats and frames: docs/export.md.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import check_new_file, check_writable, write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.export.documents import chain_document, chain_from_document, dh_document, mdh_document
from pipeline.export.rigid import RigidLoss, rigid_signature
from pipeline.export.sidecar import check_sidecar, sidecar_document, sidecar_path
from pipeline.export.urdf import (
    BASE_LINK,
    M_PER_CM,
    as_written,
    camera_origins,
    chain_from_origins,
    fixed_origins,
    joint_origins,
    link_names,
    urdf_text,
    written_origins,
)
from pipeline.kinematics.chain import SerialChain, forward_kinematics, in_frame
from pipeline.kinematics.dh_table import (
    DHTable,
    ModifiedDHTable,
    chain_from_dh_table,
    chain_from_modified,
    dh_table_from_chain,
    modified_from_dh,
)
from pipeline.kinematics.transforms import invert_transform, pose_error
from pipeline.signature.alignment import FRAMES
from pipeline.signature.file import FILE_NAME, Signature, signature_from_document
from pipeline.signature.session import load_session_document
from pipeline.signature.verdict import verdict_gate
from pipeline.units import joints_to_internal

#: The formats of :func:`export` (a chain in armsig's frames), and every ``--format``:
#: ``ur-kinematics`` is :func:`pipeline.export.ur_kinematics.export_ur_kinematics`,
#: ``camera-info`` :func:`pipeline.export.camera_info.export_camera_info`.
CHAIN_FORMATS = ("urdf", "dh", "mdh", "json")
FORMATS = (*CHAIN_FORMATS, "ur-kinematics", "camera-info")
#: The world frame of each format when ``--frame`` is not given: a URDF's root is the robot's
#: base (ROS's ``base_link``); the tables and the chain JSON keep the signature's own frame.
DEFAULT_FRAME = {"urdf": "design-base", "dh": "sensor", "mdh": "sensor", "json": "sensor"}
EXPORT_DIR = "export"
_SUFFIX = {"urdf": ".urdf", "dh": ".dh.json", "mdh": ".mdh.json", "json": ".chain.json"}
#: What the warning calls each format (each holds a rigid chain).
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
    sidecar_warning: str | None = None  # what the file loses, and where the terms are
    rigid_loss: RigidLoss | None = None  # the file against the whole signature

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


def onto_line(G: np.ndarray, K: np.ndarray, point: np.ndarray, direction: np.ndarray,
              prismatic: bool) -> np.ndarray:  # fmt: skip
    """``G · Δ``: a frame ``G`` (4, 4, in the frame after a joint) moved the least so that
    the joint's axis there, ``K⁻¹ · z`` (``K = K̄``, the link after the joint's motion),
    is the line ``point + λ · direction`` in the moved frame (a unit ``direction``; for a
    prismatic joint, the direction only: a slide has no line)."""
    L = invert_transform(G) @ invert_transform(K)
    p, u, w = L[:3, 3], L[:3, 2], np.asarray(direction, float)
    k, c = np.cross(u, w), float(np.dot(u, w))
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    D = np.eye(4)  # Δ⁻¹: the shortest turn of u onto w (Rodrigues), then p onto the line
    D[:3, :3] = np.eye(3) + Kx + Kx @ Kx / (1.0 + c)
    if not prismatic:
        off = D[:3, :3] @ p - point
        D[:3, 3] = -(off - np.dot(off, w) * w)
    out: np.ndarray = G @ invert_transform(D)
    return out


def tool0_from_last(sig: Signature, design: bool) -> np.ndarray:
    """The physical flange (ROS-I ``tool0``, the design model's last D-H frame) in the last
    link frame ``F_n`` of the exported chain, (4, 4) cm.

    The design alignment places it: ``F_signature(q) ≈ X · F_design(q) · Y`` with
    ``F_design = … · F_n^design · tool_design``, so the design flange on the signature is
    ``F_signature(q) · Y⁻¹ · tool_design⁻¹``, rigid with the last link:
    ``F_n(q) · tool · Y⁻¹ · tool_design⁻¹``, then moved the least (:func:`onto_line`) so
    that the identified last joint axis is where the design has it in its flange frame
    (a flange turns about its own axis; the least-squares ``Y`` does not know that). The
    design model: ``I`` (its own ``F_n``)."""
    if design:
        return np.eye(4)
    T = sig.chain.tool @ invert_transform(sig.design_flange_to_tool)
    T = T @ invert_transform(sig.robot.tool.matrix())
    axis = invert_transform(sig.robot.design_chain().links[-1])  # the design's, in F_n
    return onto_line(T, sig.chain.links[-1], axis[:3, 3], axis[:3, 2], bool(sig.prismatic[-1]))


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


def camera_frame(sig: Signature, chain: SerialChain, robot: Any) -> tuple[str, np.ndarray] | None:
    """A camera session's camera in the URDF (issue 39): its parent link and its optical
    frame there (cm): eye-to-hand the sensor frame itself, in the exported world
    (``base_link``); eye-in-hand the signature's tool, on the last joint's link. None
    without a camera."""
    if sig.camera is None:
        return None
    if sig.camera["setup"] == "eye-to-hand":
        return BASE_LINK, chain.base @ invert_transform(sig.chain.base)
    return link_names(robot)[robot.n_joints], joint_origins(chain)[-1]


def _static(T: np.ndarray, prismatic: np.ndarray) -> SerialChain:
    """A chain whose every configuration puts its tool at ``T`` (for :func:`_check`)."""
    n = len(prismatic)
    return SerialChain(np.broadcast_to(np.eye(4), (n, 4, 4)).copy(), prismatic, np.eye(4), T)


def _with_tool(chain: SerialChain, tool: np.ndarray) -> SerialChain:
    return SerialChain(chain.links, chain.prismatic, chain.base, tool, chain.joint_offsets)


def render(
    sig: Signature, chain: SerialChain, fmt: str, model: str, frame: str
) -> tuple[str, SerialChain, list[tuple[SerialChain, SerialChain]]]:
    """The file's text, the chain its numbers (as written) describe, and for a URDF the
    pair (intended, as written) of ``tool0``'s chain."""
    robot, pris = sig.robot, sig.prismatic
    if fmt == "urdf":
        where = (
            "the sonic sensor's frame"
            if frame == "sensor"
            else "the robot's base (the design base placed by the signature's design alignment)"
        )
        comment = (
            f"armsig {model} model of {robot.name}, base_link = {where}; flange and tool0 = "
            "the physical flange (ROS-Industrial: flange x, tool0 z out of the flange); tool = "
            "the measured tool point; SI units; joint variable = encoder reading (rad, m), "
            "encoder offsets in the joint origins"
        )
        name = robot.name if model == "signature" else f"{robot.name}_design"
        t0 = tool0_from_last(sig, model == "design")
        origins = written_origins(chain)
        flange, tool0 = as_written(fixed_origins(chain, t0))
        urdf_tool0 = chain_from_origins(origins, pris)
        urdf_tool0 = SerialChain(
            np.concatenate((urdf_tool0.links[:-1], (flange @ tool0)[None])), pris, urdf_tool0.base
        )
        camera = camera_frame(sig, chain, robot) if model == "signature" else None
        pairs = [(_with_tool(chain, t0), urdf_tool0)]
        if camera is not None:  # the optical frame as the two origins state it
            link, optical = as_written(camera_origins(camera[1]))
            pairs.append((_static(camera[1], pris), _static(link @ optical, pris)))
        return (
            urdf_text(chain, robot, name, comment, t0, camera),
            chain_from_origins(origins, pris),
            pairs,
        )
    if fmt == "json":
        doc = chain_document(chain, robot, model, frame)
        text = json_text(doc)
        return text, chain_from_document(json.loads(text), pris), []
    table = dh_table_from_chain(chain)
    if fmt == "dh":
        doc = dh_document(table, robot, model, frame)
        text = json_text(doc)
        return text, chain_from_dh_table(_dh_from_document(json.loads(text), pris)), []
    doc = mdh_document(modified_from_dh(table), table.hayati, robot, model, frame)
    text = json_text(doc)
    return text, chain_from_modified(_mdh_from_document(json.loads(text), pris)), []


def default_path(session_dir: Path, fmt: str, design: bool, frame: str) -> Path:
    """``SESSION/export/{signature|design}[.FRAME].{urdf,dh.json,mdh.json,chain.json}``, the
    frame named when it is not the format's :data:`DEFAULT_FRAME`."""
    named = "" if frame == DEFAULT_FRAME[fmt] else f".{frame}"
    stem = ("design" if design else "signature") + named
    return session_dir / EXPORT_DIR / (stem + _SUFFIX[fmt])


def export(
    session_dir: str | Path,
    fmt: str,
    out: str | Path | None = None,
    design: bool = False,
    frame: str | None = None,
    force: bool = False,
    accept_verdict: bool = False,
    over: str | Path | None = None,
) -> ExportResult:
    """Export a session's signature (``design``: its design model) as ``fmt``, its world
    in ``frame`` (None: the format's :data:`DEFAULT_FRAME`).

    ``out`` defaults to :func:`default_path` (armsig's own folder, rewritten every time);
    an ``out`` that exists is refused unless ``force``. A signature whose verdict is FAIL
    is refused unless ``accept_verdict`` (:func:`pipeline.signature.verdict.verdict_gate`).
    A signature with non-geometric terms also gets the sidecar of
    :func:`pipeline.export.sidecar.sidecar_path` (checked, and refused like ``out``), and
    the result says so in ``sidecar_warning``; the file then holds the rigid chain nearest
    the whole signature over the joint limits (or the configurations of the ``over``
    file), its loss in ``rigid_loss`` (:mod:`pipeline.export.rigid`). A rigid signature is
    exported as before (and its default folder loses a stale sidecar).
    """
    if fmt not in CHAIN_FORMATS:
        raise ArmsigError(
            f"unknown export format {fmt!r}",
            expected=", ".join(CHAIN_FORMATS),
            fix="ur-kinematics: pipeline.export.ur_kinematics.export_ur_kinematics"
            if fmt == "ur-kinematics"
            else "",
        )
    frame = DEFAULT_FRAME[fmt] if frame is None else frame
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
    best, loss = (sig, None) if design else rigid_signature(sig, sdir, over)
    chain = export_chain(best, design, frame)
    text, written, frames = render(best, chain, fmt, model, frame)
    q = random_readings(sig, CHECK_CONFIGURATIONS)
    pos, rot = _check(chain, written, q)
    for intended, as_text in frames:  # the URDF's tool0 (its flange is tool0 turned)
        _check(intended, as_text, q)
    full = export_chain(sig, design, frame)
    side_warning = write_sidecar(sig, section, path, q, _NAME[fmt], out is None,
                                 (full, frame, loss))  # fmt: skip
    write_text_atomic(path, text)
    status = None if sig.verdict is None else sig.verdict.status
    return ExportResult(
        str(path), fmt, model, frame, CHECK_CONFIGURATIONS, pos, rot, status, warning,
        str(side) if section else None, side_warning, loss if section else None,
    )  # fmt: skip


def write_sidecar(
    sig: Signature,
    section: dict[str, Any] | None,
    path: Path,
    q: np.ndarray,
    what: str,
    own_folder: bool,
    whole: tuple[SerialChain, str, RigidLoss | None],
) -> str | None:
    """Before the export ``path`` (a ``what``: "URDF", ...) is written: the whole
    signature beside it (its non-geometric ``section`` and ``whole``: its rigid chain in
    the export's frame, that frame's name and what the file loses against it; checked at
    readings ``q``), and the warning that says so; None for a rigid signature (whose
    ``own_folder`` loses a stale sidecar). The terms go first: the export never stands
    without them."""
    side = sidecar_path(path)
    if not section:
        if own_folder:  # no stale terms beside a rigid export in armsig's own folder
            side.unlink(missing_ok=True)
        return None
    full, frame, loss = whole
    assert loss is not None  # a signature with terms has its rigid loss
    side_text = json_text(sidecar_document(sig, section, path.name, full, frame, loss))
    check_sidecar(json.loads(side_text), sig, q, full)
    write_text_atomic(side, side_text)
    n = len(section["terms"])
    terms = "1 non-geometric term" if n == 1 else f"{n} non-geometric terms"
    return (
        f"{loss.text(f'the {what}')}; the whole signature (its {terms} and the chain "
        f"they go with) is written beside it in {side}"
    )
