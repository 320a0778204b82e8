"""``export --onto VENDOR.urdf``: the signature written into the vendor's own description.

The vendor's file keeps every byte but the ``<origin>`` of the joints armsig maps (its
links, meshes, inertias, limits, extra frames, comments stay), plus one fixed link
``armsig_tool`` at the measured tool point. The math (docs/export.md, "Onto a vendor URDF"):

1. Same robot. Joint ``i`` of the robot description is the vendor joint of that name (or
   ``NAME_joint``, or ``--joint-map``); fixed joints may lie between them. The vendor's
   reading is ``v = s·q + c`` (:func:`pipeline.kinematics.conventions.reading_conventions`);
   then the vendor link frame ``V_i(v)`` (the child link of joint ``i``) must equal
   ``B · D_i(q) · C_i`` with ``D_i`` the design model's frame ``i`` (z on joint ``i+1``), ``B``
   the vendor root in the design base (found with the conventions) and ``C_i`` constant:
   over random configurations each ``C_i`` must stay constant within 1e-6 m and
   1e-6 rad, else the file is refused naming the joint.
2. Calibrated. The vendor's link ``i`` goes where the signature puts link ``i``:
   ``V'_i(v) = B · X⁻¹ · S_i(q) · G_i`` (``S_i``: signature frame ``i`` in the sensor frame,
   ``X``: sensor from design base). ``G_i`` is the vendor frame's place on the signature's
   link: the mean over the design alignment's configurations of ``S_i⁻¹ X B⁻¹ V_i``, on the
   last link exactly the alignment's flange (``tool · Y⁻¹ · tool_design⁻¹ · C_n``), then
   moved the least onto the identified axis of joint ``i`` (a URDF joint turns its child
   about an axis through the child's origin). The vendor root is ``B`` from the design
   base, itself placed by the design alignment.
3. Origins. ``V'_i = V'_{i−1} · P_i · O'_i · M(axis_i, v_i)`` (``P_i``: the fixed joints
   between) gives ``O'_i = P_i⁻¹ G_{i−1}⁻¹ M(z, −q0_i − s_i c_i) K̄_i G_i``: constant in
   ``q``, with the encoder offset ``q0_i``.

The file as written is read back and its links are evaluated at 1,000 configurations
against the signature before anything is written (1e-9 m, 1e-9 rad).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from pipeline.atomic import atomic_write, check_new_file, check_writable
from pipeline.errors import ArmsigError, KinematicsError
from pipeline.export import (
    CHECK_CONFIGURATIONS,
    CHECK_ORIENTATION_RAD,
    CHECK_POSITION_M,
    EXPORT_DIR,
    onto_line,
    random_readings,
    tool0_from_last,
    write_sidecar,
)
from pipeline.export.rigid import RigidLoss, rigid_signature
from pipeline.export.sidecar import sidecar_path
from pipeline.export.urdf import M_PER_CM, origin_element
from pipeline.export.vendor import (
    VendorJoint,
    VendorURDF,
    arm_root,
    axis_frame,
    motion,
    parse_vendor_urdf,
    path_to,
    read_vendor_urdf,
)
from pipeline.kinematics.chain import SerialChain, in_frame, link_frames
from pipeline.kinematics.conventions import Conventions, reading_conventions
from pipeline.kinematics.transforms import (
    Array,
    invert_transform,
    pose_error,
    rot_z,
    trans_z,
    wrap_angle,
)
from pipeline.robots.description import RobotDescription
from pipeline.signature.alignment import ALIGNMENT_SAMPLES
from pipeline.signature.file import FILE_NAME, Signature, signature_from_document
from pipeline.signature.session import load_session_document
from pipeline.signature.verdict import verdict_gate

TOOL_LINK = "armsig_tool"
#: The vendor file and armsig's design are one robot when every link frame of one stays
#: within this of a constant transform of the other's (m, rad): a vendor's rounded
#: constants (π/2 as 1.57079632679) are ~1e-11 off; another robot is centimetres off.
SAME_ROBOT_M = 1e-6
SAME_ROBOT_RAD = 1e-6
#: Configurations of the same-robot check (within the description's limits, seed 1).
SAME_ROBOT_CONFIGURATIONS = 200


@dataclass(frozen=True)
class OntoResult:
    """What was written, how the vendor file matched, and how far the calibration moved
    each joint origin."""

    path: str
    vendor: str
    joints: dict[str, str]  # armsig joint -> vendor joint
    vendor_sign: list[float]  # v = sign · q + offset
    vendor_offset: list[float]  # deg / cm
    conventions_warning: str | None  # where the vendor reads joints otherwise
    same_robot_m: float  # largest variation of a C_i (m)
    same_robot_rad: float
    origin_moves_mm: dict[str, float]  # per vendor joint: calibrated origin − vendor's
    origin_moves_deg: dict[str, float]
    configurations: int
    max_position_error_m: float
    max_orientation_error_rad: float
    vendor_root_from_design_base: list[list[float]]  # B, cm
    verdict: str | None = None
    verdict_warning: str | None = None
    sidecar: str | None = None
    sidecar_warning: str | None = None
    rigid_loss: RigidLoss | None = None  # the file against the whole signature

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class VendorChain:
    """The mapped joints of a vendor file, base to tip, and the fixed transforms before
    each (``P_i``, cm)."""

    joints: list[VendorJoint]
    before: Array  # (n, 4, 4)

    def frames(self, v: Array) -> Array:
        """Child-link frames ``V_i(v)`` (m, n, 4, 4) in the vendor root, cm, of readings
        ``v`` (m, n), rad / cm."""
        V = np.empty((*v.shape, 4, 4))
        T = np.broadcast_to(np.eye(4), (len(v), 4, 4))
        for i, j in enumerate(self.joints):
            T = T @ self.before[i] @ j.origin @ motion(j, v[:, i])
            V[:, i] = T
        return V

    def as_chain(self) -> SerialChain:
        """The same kinematics as armsig's chain (5.1)-(5.3), z turned onto each axis:
        base ``P_1 O_1 R_1``, links ``R_i⁻¹ P_{i+1} O_{i+1} R_{i+1}``, last ``I``."""
        R = [axis_frame(j.axis) for j in self.joints]
        M = [self.before[i] @ j.origin @ R[i] for i, j in enumerate(self.joints)]
        links = [R[i].T @ M[i + 1] for i in range(len(M) - 1)] + [np.eye(4)]
        pris = np.array([j.type == "prismatic" for j in self.joints])
        return SerialChain(np.stack(links), pris, M[0])


def vendor_chain(urdf: VendorURDF, names: list[str]) -> VendorChain:
    """The vendor joints ``names`` as one serial chain from the root, or a one-line
    refusal (a moving joint between them, or not in this order)."""
    joints: list[VendorJoint] = []
    before: list[Array] = []
    link = arm_root(urdf, names[0])
    for name in names:
        j = urdf.joints[name]
        path = path_to(urdf, j.parent, link)
        if path is None:
            after = repr(joints[-1].name) if joints else "the root"
            raise ArmsigError(
                f"{urdf.path}: joint {name!r} does not follow {after}",
                expected="the mapped joints in the robot description's order, base to tip",
            )
        moving = [p.name for p in path if p.moving]
        if moving:
            raise ArmsigError(
                f"{urdf.path}: moving joint {moving[0]!r} lies between the mapped joints",
                fix="map it with --joint-map, or use a description with that joint",
            )
        P = np.eye(4)
        for p in path:
            P = P @ p.origin
        joints.append(j)
        before.append(P)
        link = j.child
    return VendorChain(joints, np.stack(before))


def joint_names(sig: Signature, urdf: VendorURDF, joint_map: str | None) -> dict[str, str]:
    """armsig joint -> vendor joint: ``--joint-map armsig=vendor,...``, else the same name,
    else ``NAME_joint``; a one-line refusal naming what is missing."""
    given: dict[str, str] = {}
    for item in (joint_map or "").split(","):
        if not item.strip():
            continue
        a, sep, b = item.partition("=")
        if not sep or not a.strip() or not b.strip():
            raise ArmsigError("--joint-map: a pair is not armsig=vendor", got=repr(item))
        given[a.strip()] = b.strip()
    mine = [j.name for j in sig.robot.joints]
    extra = sorted(set(given) - set(mine))
    if extra:
        raise ArmsigError(
            f"--joint-map names unknown armsig joints {extra}", expected=", ".join(mine)
        )
    moving = [j.name for j in urdf.joints.values() if j.arm_joint]
    out = {}
    for j in sig.robot.joints:
        v = given.get(j.name) or next((x for x in (j.name, f"{j.name}_joint") if x in moving), None)
        if v is None or v not in urdf.joints or not urdf.joints[v].arm_joint:
            raise ArmsigError(
                f"{urdf.path}: no moving joint for armsig's joint {j.name!r}"
                + (f" (--joint-map gives {v!r})" if v else ""),
                expected=f"one of {', '.join(moving)}",
                fix="--joint-map armsig=vendor,... (docs/export.md)",
            )
        kind = "prismatic" if j.prismatic else "revolute"
        if (urdf.joints[v].type == "prismatic") != j.prismatic:
            raise ArmsigError(
                f"{urdf.path}: joint {v!r} is {urdf.joints[v].type}, armsig's {j.name!r} {kind}"
            )
        out[j.name] = v
    return out


def mean_transform(T: Array) -> Array:
    """The mean (4, 4) of transforms (m, 4, 4): mean translation, and the rotation nearest
    the mean rotation matrix (SVD)."""
    U, _, Vt = np.linalg.svd(T[:, :3, :3].sum(axis=0))
    out = np.eye(4)
    out[:3, :3] = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    out[:3, 3] = T[:, :3, 3].mean(axis=0)
    return out


def _spread(T: Array) -> tuple[float, float]:
    """How far transforms (m, 4, 4) stray from their mean: metres, radians."""
    dp, dr = pose_error(np.broadcast_to(mean_transform(T), T.shape), T)
    return float(dp.max()) * M_PER_CM, float(dr.max())


def _mot(prismatic: bool, x: float) -> Array:
    out: Array = trans_z(x) if prismatic else rot_z(x)
    return out


@dataclass(frozen=True)
class Calibration:
    """The vendor chain calibrated (module docstring), cm: the new joint ``origins``
    (n, 4, 4), the ``armsig_tool`` origin on the last mapped link, ``B`` (the vendor root
    in the design base), the vendor frames ``G_i`` on the signature's links, ``BX`` (the
    vendor root from the sensor frame, ``B · X⁻¹``), the reading conventions and how
    constant the design-to-vendor transforms stayed (m, rad)."""

    chain: VendorChain
    conventions: Conventions
    origins: Array
    tool: Array
    B: Array
    G: list[Array]
    BX: Array
    same_robot: tuple[float, float]


def match_vendor(
    robot: RobotDescription, urdf: VendorURDF, names: list[str]
) -> tuple[VendorChain, Conventions, list[Array], tuple[float, float]]:
    """The vendor joints ``names`` as a chain, how the vendor reads them, the constant
    ``C_i`` of each link against the design's, and how constant they stayed (m, rad):
    the same-robot check (module docstring, 1.), ArmsigError when the file is another
    robot."""
    vc = vendor_chain(urdf, names)
    design = robot.design_chain()
    try:
        conv = reading_conventions(design, vc.as_chain(), [j.name for j in robot.joints])
    except KinematicsError as exc:
        raise ArmsigError(f"{urdf.path} is not the robot {robot.name}: {exc}") from exc

    def v_of(q: Array) -> Array:
        return q * conv.sign + conv.offset

    B = conv.world  # the vendor root in the design base
    q = robot.random_configurations(SAME_ROBOT_CONFIGURATIONS, 1)
    V = vc.frames(v_of(q))
    D = link_frames(design, q)[:, 1:-1]  # frame i: after joint i, z on joint i+1
    Cq = invert_transform(B @ D) @ V
    worst_m, worst_rad = 0.0, 0.0
    for i, j in enumerate(vc.joints):
        m, r = _spread(Cq[:, i])
        if not (m <= SAME_ROBOT_M and r <= SAME_ROBOT_RAD):
            raise ArmsigError(
                f"{urdf.path} is not the robot {robot.name}: its link {j.child!r} (after "
                f"joint {j.name!r}) moves against armsig's design link by {m * 1e3:.3g} mm, "
                f"{np.degrees(r):.3g} deg over {len(q)} configurations",
                expected=f"a constant transform, within {SAME_ROBOT_M:g} m, {SAME_ROBOT_RAD:g} rad",
                fix="export onto this robot model's own URDF, or check --joint-map",
            )
        worst_m, worst_rad = max(worst_m, m), max(worst_rad, r)
    C = [mean_transform(Cq[:, i]) for i in range(len(vc.joints))]
    return vc, conv, C, (worst_m, worst_rad)


def calibrate(sig: Signature, urdf: VendorURDF, names: list[str]) -> Calibration:
    """The same-robot check and the calibrated origins (module docstring); ArmsigError
    when the file is another robot."""
    robot, chain = sig.robot, sig.chain
    vc, conv, C, worst = match_vendor(robot, urdf, names)
    B = conv.world  # the vendor root in the design base

    def v_of(q: Array) -> Array:
        return q * conv.sign + conv.offset

    # 2. the calibrated vendor link frames, G_i in the signature's frame i
    X = sig.sensor_from_design_base
    XB = X @ invert_transform(B)
    qa = robot.random_configurations(ALIGNMENT_SAMPLES, 0)
    S = link_frames(chain, qa)
    Vd = vc.frames(v_of(qa))
    G = [mean_transform(invert_transform(S[:, i + 1]) @ XB @ Vd[:, i]) for i in range(len(C))]
    G[-1] = tool0_from_last(sig, False) @ C[-1]  # the alignment's flange, exactly
    pris = robot.prismatic
    # each on the identified axis of its joint, through its origin (a URDF joint's child)
    G = [
        onto_line(G[i], chain.links[i], np.zeros(3), conv.sign[i] * j.axis, bool(pris[i]))
        for i, j in enumerate(vc.joints)
    ]
    before = [invert_transform(chain.base) @ XB] + G[:-1]  # G_{i−1}; the root's: V'_0 = I
    q0 = np.asarray(chain.joint_offsets)
    origins = np.stack([
        invert_transform(vc.before[i]) @ invert_transform(before[i])
        @ _mot(bool(pris[i]), -q0[i] - conv.sign[i] * conv.offset[i])
        @ chain.links[i] @ G[i]
        for i in range(len(G))
    ])  # fmt: skip
    tool = invert_transform(G[-1]) @ chain.tool
    BX = invert_transform(XB)
    return Calibration(vc, conv, origins, tool, B, G, BX, worst)


def _comment(text: str) -> str:
    return f"<!-- {text.replace('--', '-')} -->"  # "--" may not stand in an XML comment


def _xml_tool(parent: str, origin: Array, session: str) -> bytes:
    return (
        f"  {_comment(f'armsig: the measured tool point of session {session}')}\n"
        f'  <link name="{TOOL_LINK}"/>\n'
        f'  <joint name="{TOOL_LINK}_joint" type="fixed">\n'
        f'    <parent link={quoteattr(parent)}/>\n    <child link="{TOOL_LINK}"/>\n'
        f"    {origin_element(origin)}\n  </joint>\n"
    ).encode()


def calibrated_bytes(urdf: VendorURDF, cal: Calibration, session: str) -> bytes:
    """The vendor file with the mapped joints' ``<origin>`` replaced (or inserted), a
    comment after the XML declaration and the ``armsig_tool`` link before ``</robot>``."""
    data = urdf.data
    if TOOL_LINK in urdf.links:
        raise ArmsigError(f"{urdf.path} already has a link named {TOOL_LINK!r}")
    edits: list[tuple[int, int, bytes]] = []
    for j, origin in zip(cal.chain.joints, cal.origins, strict=True):
        new = origin_element(origin).encode()
        if j.origin_span is None:
            edits.append((j.body_start, j.body_start, b"\n    " + new))
        else:
            edits.append((*j.origin_span, new))
    end = data.rindex(b"</robot>")
    edits.append((end, end, _xml_tool(cal.chain.joints[-1].child, cal.tool, session)))
    decl = data.find(b"?>") + 2 if data.lstrip().startswith(b"<?xml") else 0
    note = "\n" + _comment(
        f"calibrated by armsig (session {session}): the <origin> of the joints "
        f"{', '.join(j.name for j in cal.chain.joints)} hold the identified geometry and "
        "encoder offsets (docs/export.md); everything else is the vendor's file"
    )
    edits.append((decl, decl, (note if decl else note.lstrip() + "\n").encode()))
    for a, b, text in sorted(edits, key=lambda e: e[0], reverse=True):
        data = data[:a] + text + data[b:]
    return data


def check_calibrated(
    sig: Signature, data: bytes, path: Path, names: list[str], cal: Calibration
) -> tuple[float, float]:
    """Read ``data`` back as a URDF and compare its mapped links and ``armsig_tool`` with
    the signature at :data:`CHECK_CONFIGURATIONS` readings; RuntimeError (a bug) above
    :data:`CHECK_POSITION_M` / :data:`CHECK_ORIENTATION_RAD`."""
    back = parse_vendor_urdf(data, path)
    vc = vendor_chain(back, names)
    conv = cal.conventions
    q = random_readings(sig, CHECK_CONFIGURATIONS)
    V = vc.frames(q * conv.sign + conv.offset)
    tool = back.joints[f"{TOOL_LINK}_joint"].origin
    S = link_frames(sig.chain, q)
    BX = cal.BX
    want = np.concatenate(
        [BX @ S[:, i + 1] @ cal.G[i] for i in range(len(names))] + [BX @ S[:, -1]]
    )
    got = np.concatenate([V[:, i] for i in range(len(names))] + [V[:, -1] @ tool])
    dp, dr = pose_error(want, got)
    pos, rot = float(dp.max()) * M_PER_CM, float(dr.max())
    if not (pos <= CHECK_POSITION_M and rot <= CHECK_ORIENTATION_RAD):
        raise RuntimeError(f"the calibrated URDF does not reproduce the signature: {pos:.3e} m")
    return pos, rot


def vendor_output(sdir: Path, src: Path, out: str | Path | None, force: bool, kind: str) -> Path:
    """Where a file written onto the vendor URDF ``src`` goes: ``out`` (an existing one
    needs ``force``; never the vendor file itself), else ``SESSION/export/<vendor
    stem>.<kind>.urdf`` (armsig's folder, rewritten)."""
    if out is None:
        path = sdir / EXPORT_DIR / f"{src.stem}.{kind}.urdf"
        check_writable(path.parent, "export folder", folder=True)
        return path
    path = Path(out)
    if path.exists() and path.resolve() == src.resolve():
        raise ArmsigError(f"--out {path} is the vendor file itself",
                          fix=f"write the {kind} file elsewhere")  # fmt: skip
    return check_new_file(out, "--out", force)


def export_onto(
    session_dir: str | Path,
    vendor: str | Path,
    out: str | Path | None = None,
    joint_map: str | None = None,
    force: bool = False,
    accept_verdict: bool = False,
    over: str | Path | None = None,
) -> OntoResult:
    """Write the vendor URDF ``vendor`` calibrated by the session's signature (module
    docstring). ``out`` defaults to ``SESSION/export/<vendor stem>.calibrated.urdf``
    (armsig's folder, rewritten); an existing ``out`` needs ``force``, and ``out`` is
    never the vendor file itself. A signature with non-geometric terms is written as the
    rigid chain nearest it over the joint limits (or the ``over`` file's configurations;
    :mod:`pipeline.export.rigid`)."""
    sdir, src = Path(session_dir), Path(vendor)
    urdf = read_vendor_urdf(src)
    path = vendor_output(sdir, src, out, force, "calibrated")
    doc = load_session_document(sdir / FILE_NAME)
    sig = signature_from_document(doc, str(sdir / FILE_NAME))
    warning = verdict_gate(sig.verdict, str(sdir), accept_verdict)
    section = doc.get("nongeometric")
    if section and out is not None:
        check_new_file(sidecar_path(path), "sidecar", force)
    mapping = joint_names(sig, urdf, joint_map)
    names = list(mapping.values())
    best, loss = rigid_signature(sig, sdir, over)  # the rigid chain nearest the whole signature
    cal = calibrate(best, urdf, names)
    data = calibrated_bytes(urdf, cal, sdir.name)
    pos, rot = check_calibrated(best, data, path, names, cal)
    full = in_frame(sig.chain, invert_transform(cal.BX))  # the signature's, vendor root
    side_warning = write_sidecar(sig, section, path, random_readings(sig, CHECK_CONFIGURATIONS),
                                 "URDF", out is None, (full, "vendor-root", loss))  # fmt: skip
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as f:  # the vendor's bytes, in the vendor's encoding
        f.write(urdf.encoded(data))  # type: ignore[arg-type]
    moves_mm, moves_deg = {}, {}
    for j, origin in zip(cal.chain.joints, cal.origins, strict=True):
        dp, dr = pose_error(j.origin, origin)
        moves_mm[j.name], moves_deg[j.name] = float(dp) * 10.0, float(np.degrees(dr))
    conv = cal.conventions
    off = np.where(sig.prismatic, conv.offset, np.degrees(wrap_angle(conv.offset)))
    return OntoResult(
        path=str(path), vendor=str(src), joints=mapping, vendor_sign=conv.sign.tolist(),
        vendor_offset=off.tolist(), conventions_warning=_conventions_warning(mapping, conv, off),
        same_robot_m=cal.same_robot[0], same_robot_rad=cal.same_robot[1],
        origin_moves_mm=moves_mm, origin_moves_deg=moves_deg,
        configurations=CHECK_CONFIGURATIONS, max_position_error_m=pos,
        max_orientation_error_rad=rot, vendor_root_from_design_base=cal.B.tolist(),
        verdict=None if sig.verdict is None else sig.verdict.status, verdict_warning=warning,
        sidecar=str(sidecar_path(path)) if section else None, sidecar_warning=side_warning,
        rigid_loss=loss if section else None,
    )  # fmt: skip


#: Offsets below this (deg / cm) are the vendor's rounding, not another zero.
ROUNDING = 1e-6


def _conventions_warning(mapping: dict[str, str], conv: Conventions, off: Array) -> str | None:
    """Where the vendor reads a joint otherwise than armsig (sign, offset): which, and that
    the controller must report the vendor's readings; None when it reads the same."""
    other = [
        f"{v} = {'-' if s < 0 else ''}{a}{f' {o:+.6g}' if abs(o) > ROUNDING else ''}"
        for (a, v), s, o in zip(mapping.items(), conv.sign, off, strict=True)
        if s < 0 or abs(o) > ROUNDING
    ]
    if not other:
        return None
    alt = (
        f"; {conv.alternatives} other conventions fit this geometry as well"
        if conv.alternatives
        else ""
    )
    return (
        f"the vendor file reads joints otherwise than the robot description ({', '.join(other)}; "
        f"deg / cm){alt}: the calibrated file is right for a controller that reports the "
        "vendor's readings"
    )
