"""``export --onto VENDOR.urdf --offsets-only``: the signature as joint offsets alone, in
the ``<calibration rising="..."/>`` tags that ``robot_calibration`` writes and its drivers
read (a joint's position is its reading plus the offset; robot_calibration's
``OptimizationOffsets::updateURDF``), the vendor's geometry kept byte for byte.

A driver that takes joint offsets only cannot hold the rest of a signature. The file holds
the offsets ``δ`` that bring the vendor's own chain nearest the whole signature at the
tool point (:func:`pipeline.refine.baseline.register_offsets`, least squares over the
joint limits or ``--over``'s configurations, with the robot's base and the tool point
fitted too), and the export states what it loses (RMS, max). Joint 1's offset is the
base's turn about joint 1's axis, which points cannot tell apart: it is held at 0 (the
base carries it); so is the offset of a joint whose direction the session's own fit held
(a tool point on its axis). A vendor file whose mapped joints hold offsets already is
refused: armsig's readings are the controller's own, before any offset. The file as
written is read back and its tool point, at the readings plus the offsets read from it,
must be the fit's to 1e-9 m. The vendor file's other bytes are unchanged but for one
fixed link ``armsig_tool`` at the fitted tool point.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import atomic_write
from pipeline.errors import ArmsigError
from pipeline.export import CHECK_POSITION_M
from pipeline.export.onto import (
    TOOL_LINK,
    _xml_tool,
    joint_names,
    match_vendor,
    vendor_chain,
    vendor_output,
)
from pipeline.export.rigid import MM_PER_CM, fit_readings, over_readings, session_held
from pipeline.export.urdf import M_PER_CM
from pipeline.export.vendor import VendorURDF, axis_frame, parse_vendor_urdf, read_vendor_urdf
from pipeline.kinematics.chain import forward_kinematics, link_frames
from pipeline.kinematics.transforms import Array, invert_transform
from pipeline.refine.baseline import register_offsets
from pipeline.signature.file import FILE_NAME, Signature, signature_from_document
from pipeline.signature.session import load_session_document
from pipeline.signature.verdict import verdict_gate

_END = re.compile(rb"</joint\s*>")
_CALIBRATION = re.compile(rb"<calibration\b[^>]*>")
_RISING = re.compile(rb'rising\s*=\s*(["\'])([^"\']*)\1')


@dataclass(frozen=True)
class OffsetsResult:
    """What was written: the offsets per vendor joint (deg / cm, added to the vendor's
    readings; 0 where held), and what the file loses against the whole signature."""

    path: str
    vendor: str
    joints: dict[str, str]  # armsig joint -> vendor joint
    offsets: dict[str, float]  # vendor joint -> offset written (deg / cm)
    held: list[str]  # vendor joints whose offset is held at 0
    configurations: int
    over: str
    rms_mm: float
    max_mm: float
    max_position_error_m: float  # the file as written against the fit
    verdict: str | None = None
    verdict_warning: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def text(self) -> str:
        return (
            f"the URDF holds joint offsets only: it loses {self.rms_mm:.3f} mm RMS, "
            f"{self.max_mm:.3f} mm max at the tool point against the whole signature over "
            f"{self.configurations:,} configurations {self.over}"
        )


def _joint_span(data: bytes, start: int) -> tuple[int, int]:
    end = _END.search(data, start)
    if end is None:
        raise ArmsigError("a <joint> element is not closed", got=f"byte {start}")
    return start, end.start()


def rising_of(data: bytes, urdf: VendorURDF, name: str) -> float:
    """The ``rising`` of joint ``name``'s ``<calibration>`` in ``data`` (0: none)."""
    a, b = _joint_span(data, urdf.joints[name].body_start)
    tag = _CALIBRATION.search(data, a, b)
    m = None if tag is None else _RISING.search(tag.group(0))
    if m is None:
        return 0.0
    try:
        return float(m.group(2))
    except ValueError as exc:
        raise ArmsigError(f"{urdf.path}: joint {name!r} calibration rising is not a number",
                          got=m.group(2).decode(errors="replace")) from exc  # fmt: skip


def with_offsets(urdf: VendorURDF, offsets: dict[str, float], tool: bytes) -> bytes:
    """The vendor's bytes with each joint's ``rising`` set to ``offsets`` (URDF units; the
    file's own are 0), a ``<calibration>`` added where there is none, and ``tool`` before
    ``</robot>``."""
    data = urdf.data
    edits: list[tuple[int, int, bytes]] = []
    for name, delta in offsets.items():
        if delta == 0.0:
            continue
        a, b = _joint_span(data, urdf.joints[name].body_start)
        new = repr(float(delta)).encode()
        tag = _CALIBRATION.search(data, a, b)
        m = None if tag is None else _RISING.search(tag.group(0))
        if tag is not None and m is not None:
            edits.append((tag.start() + m.start(2), tag.start() + m.end(2), new))
        elif tag is not None:  # a <calibration> without rising: give it one
            edits.append((tag.start() + len(b"<calibration"),) * 2 + (b' rising="' + new + b'"',))
        else:
            edits.append((b, b, b'  <calibration rising="' + new + b'"/>\n  '))
    end = data.rindex(b"</robot>")
    edits.append((end, end, tool))
    for a, b, text in sorted(edits, key=lambda e: e[0], reverse=True):
        data = data[:a] + text + data[b:]
    return data


def export_offsets(
    session_dir: str | Path,
    vendor: str | Path,
    out: str | Path | None = None,
    joint_map: str | None = None,
    force: bool = False,
    accept_verdict: bool = False,
    over: str | Path | None = None,
) -> OffsetsResult:
    """Write the vendor URDF ``vendor`` with the signature as joint offsets (module
    docstring); ``out`` defaults to ``SESSION/export/<vendor stem>.offsets.urdf``."""
    sdir, src = Path(session_dir), Path(vendor)
    urdf = read_vendor_urdf(src)
    path = vendor_output(sdir, src, out, force, "offsets")
    if TOOL_LINK in urdf.links:
        raise ArmsigError(f"{urdf.path} already has a link named {TOOL_LINK!r}")
    doc = load_session_document(sdir / FILE_NAME)
    sig = signature_from_document(doc, str(sdir / FILE_NAME))
    warning = verdict_gate(sig.verdict, str(sdir), accept_verdict)
    mapping = joint_names(sig, urdf, joint_map)
    names = list(mapping.values())
    vc, conv, _, _ = match_vendor(sig.robot, urdf, names)
    already = [n for n in names if rising_of(urdf.data, urdf, n) != 0.0]
    if already:
        raise ArmsigError(
            f"{urdf.path}: joint {already[0]!r} holds a calibration offset already",
            expected="the vendor's uncalibrated URDF (armsig's readings are the controller's "
            "own, before any offset)",
            fix="export onto the file without <calibration rising> tags",
        )
    q = fit_readings(sig) if over is None else over_readings(sig, over)
    fit, held = _fit(sig, sdir, q, vc, conv)
    pris = sig.prismatic
    urdf_units = np.where(pris, fit.offsets * M_PER_CM, fit.offsets)
    tool = axis_frame(vc.joints[-1].axis)
    tool[:3, 3] = tool[:3, :3] @ fit.tool  # the tool point in the last mapped link
    tool[:3, :3] = np.eye(3)
    data = with_offsets(urdf, dict(zip(names, urdf_units.tolist(), strict=True)),
                        _xml_tool(vc.joints[-1].child, tool, sdir.name))  # fmt: skip
    err = _check(data, path, names, conv, fit, q)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as f:  # the vendor's bytes, in the vendor's encoding
        f.write(urdf.encoded(data))  # type: ignore[arg-type]
    shown = np.where(pris, fit.offsets, np.degrees(fit.offsets))
    return OffsetsResult(
        str(path), str(src), mapping, dict(zip(names, shown.tolist(), strict=True)),
        [v for v, h in zip(names, held, strict=True) if h], len(q),
        "within the joint limits" if over is None else f"of {Path(over).name}",
        float(np.sqrt(np.mean(fit.errors_cm**2))) * MM_PER_CM,
        float(fit.errors_cm.max()) * MM_PER_CM, err,
        None if sig.verdict is None else sig.verdict.status, warning,
    )  # fmt: skip


def _fit(sig: Signature, sdir: Path, q: Array, vc: Any, conv: Any) -> tuple[Any, Array]:
    """The offsets fit (module docstring) at readings ``q``: the whole signature's tool
    point, the vendor chain at the vendor's readings."""
    target = q if sig.nongeometric is None else sig.nongeometric.effective(q)
    points = forward_kinematics(sig.chain, target)[:, :3, 3]
    held = np.zeros(sig.robot.n_joints, bool)
    held[0] = True  # joint 1's offset: the base's turn about its axis
    session = session_held(sdir)
    held |= np.array([f"joint{j + 1}.rx" in session for j in range(len(held))])
    base0 = sig.sensor_from_design_base @ invert_transform(conv.world)  # the vendor root
    fit = register_offsets(vc.as_chain(), q * conv.sign + conv.offset, points, base0, held)
    return fit, held


def rising_units(rising: Array, prismatic: Array) -> Array:
    """URDF offsets (rad / m) in armsig's units (rad / cm)."""
    out: Array = np.where(prismatic, rising / M_PER_CM, rising)
    return out


def _check(data: bytes, path: Path, names: list[str], conv: Any, fit: Any, q: Array) -> float:
    """The file as read back, at the readings plus its ``rising`` (read back), against
    the fitted tool point; a bug above :data:`CHECK_POSITION_M`."""
    back = parse_vendor_urdf(data, path)
    rising = np.array([rising_of(data, back, n) for n in names])
    pris = np.array([back.joints[n].type == "prismatic" for n in names])
    v = q * conv.sign + conv.offset + rising_units(rising, pris)
    V = vendor_chain(back, names).frames(v)[:, -1] @ back.joints[f"{TOOL_LINK}_joint"].origin
    got = V[:, :3, 3] @ fit.base[:3, :3].T + fit.base[:3, 3]
    n = len(names)
    F = link_frames(vendor_chain(back, names).as_chain(), v - rising_units(rising, pris)
                    + fit.offsets)[:, n]  # fmt: skip
    tool = np.einsum("kij,j->ki", F[:, :3, :3], fit.tool) + F[:, :3, 3]
    want = tool @ fit.base[:3, :3].T + fit.base[:3, 3]
    err = float(np.abs(got - want).max()) * M_PER_CM
    if not err <= CHECK_POSITION_M:
        raise RuntimeError(f"the offsets URDF does not reproduce the fit: {err:.3e} m")
    return err
