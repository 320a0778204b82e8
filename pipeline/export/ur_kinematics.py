"""``export --format ur-kinematics``: a UR arm's signature as ``ur_description``'s
``kinematics.yaml`` (the layout ``ur_calibration`` writes, read through the xacro's
``kinematics_parameters_file``; format in docs/export.md).

The xacro (Universal_Robots_ROS2_Description ``urdf/ur_macro.xacro``, read by
``urdf/inc/ur_common.xacro``) builds ``base_link`` → ``base_link_inertia`` (fixed, rpy
``0 0 π``) → ``shoulder_pan_joint`` (origin ``kinematics.shoulder``: x y z roll pitch yaw,
axis z) → ``shoulder_link`` → ``shoulder_lift_joint`` (``upper_arm``) → ``elbow_joint``
(``forearm``) → ``wrist_1_joint`` → ``wrist_2_joint`` → ``wrist_3_joint`` (``wrist_1``,
``wrist_2``, ``wrist_3``) → ``wrist_3_link``, then ``flange`` (rpy ``0 −π/2 −π/2``) and
``tool0`` (rpy ``π/2 0 π/2``). An origin is ``Trans(x, y, z) Rz(yaw) Ry(pitch) Rx(roll)``
(URDF), metres and radians, and a joint turns its child by ``Rz(q)``.

A UR arm here is 6 revolute joints whose design D-H rows have UR's shape (every UR3, 5,
10, 16, 20, 30 and e-series model): α = 90, 0, 0, 90, −90, 0°, θ = 0,
``a_1 = d_2 = d_3 = a_4 = a_5 = a_6 = 0``; any other chain is refused in one line. Its
design in that layout is UR's default file: ``base_link_inertia`` is D-H frame 0 and joint
``i``'s origin ``Tx(a_{i−1}) Rx(α_{i−1}) Tz(d_i)`` (``a_0 = α_0 = 0``). That design is
calibrated by the signature exactly as ``--onto`` calibrates a vendor URDF
(:func:`pipeline.export.onto.calibrate`); the six calibrated origins are the file. A
signature with non-geometric terms is written as the rigid chain nearest it
(:mod:`pipeline.export.rigid`), the whole signature beside it.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import check_new_file, check_writable, write_text_atomic
from pipeline.errors import ArmsigError
from pipeline.export import (
    CHECK_CONFIGURATIONS,
    CHECK_ORIENTATION_RAD,
    CHECK_POSITION_M,
    EXPORT_DIR,
    random_readings,
    write_sidecar,
)
from pipeline.export.onto import Calibration, calibrate
from pipeline.export.rigid import RigidLoss, rigid_signature
from pipeline.export.sidecar import sidecar_path
from pipeline.export.urdf import M_PER_CM, origin_element
from pipeline.export.vendor import parse_vendor_urdf
from pipeline.kinematics.chain import in_frame, link_frames
from pipeline.kinematics.transforms import (
    Array,
    invert_transform,
    pose_error,
    rot_x,
    rot_z,
    trans_x,
    trans_z,
    transform_from_xyz_rpy,
    xyz_rpy_from_transform,
)
from pipeline.robots.description import RobotDescription
from pipeline.signature.checks import DIGEST_KEY
from pipeline.signature.file import FILE_NAME, signature_from_document
from pipeline.signature.session import load_session_document
from pipeline.signature.verdict import verdict_gate

#: The file's sections, joint by joint, and the xacro's joint and link names.
SECTIONS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
JOINTS = tuple(f"{j}_joint" for j in ("shoulder_pan", "shoulder_lift", "elbow", *SECTIONS[3:]))
LINKS = ("base_link_inertia", "shoulder_link", "upper_arm_link", "forearm_link",
         "wrist_1_link", "wrist_2_link", "wrist_3_link")  # fmt: skip
KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
#: base_link_inertia in base_link: the xacro's rpy "0 0 ${pi}".
BASE_INERTIA = rot_z(np.pi)
#: UR's D-H shape (module docstring): α (deg) and the rows' a, d that are 0.
UR_ALPHA_DEG = (90.0, 0.0, 0.0, 90.0, -90.0, 0.0)
UR_ZERO_A = (0, 3, 4, 5)  # a_1, a_4, a_5, a_6 (0-based rows)
UR_ZERO_D = (1, 2)  # d_2, d_3
#: The design's D-H values are text (deg, cm): UR's shape holds to their last digit.
SHAPE_TOL = 1e-9
FILE = "ur_kinematics.yaml"


@dataclass(frozen=True)
class URKinematicsResult:
    """What was written, and how closely the file's chain reproduces the signature."""

    path: str
    joints: dict[str, str]  # armsig joint -> the xacro's joint
    tool_in_wrist_3_link_m: list[float]  # the measured tool point, wrist_3_link frame
    base_link_from_design_base: list[list[float]]  # cm
    configurations: int
    max_position_error_m: float
    max_orientation_error_rad: float
    hash: str
    verdict: str | None = None
    verdict_warning: str | None = None
    sidecar: str | None = None
    sidecar_warning: str | None = None
    rigid_loss: RigidLoss | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def check_ur(robot: RobotDescription) -> None:
    """Refuse in one line a robot whose design is not UR's D-H shape (module docstring)."""
    rows = [j.dh for j in robot.joints]
    why = None
    if len(rows) != 6 or robot.prismatic.any():
        why = f"{len(rows)} joints, {int(robot.prismatic.sum())} prismatic"
    else:
        alpha = np.array([r.alpha_deg for r in rows])
        a, d = np.array([r.a_cm for r in rows]), np.array([r.d_cm for r in rows])
        theta = np.array([r.theta_deg for r in rows])
        if np.abs(alpha - UR_ALPHA_DEG).max() > SHAPE_TOL:
            why = f"alpha {', '.join(f'{v:g}' for v in alpha)} deg"
        elif np.abs(np.r_[a[list(UR_ZERO_A)], d[list(UR_ZERO_D)], theta]).max() > SHAPE_TOL:
            why = "a D-H a_1, a_4-a_6, d_2, d_3 or theta offset that is not 0"
    if why is not None:
        raise ArmsigError(
            f"robot {robot.name} is not a Universal Robots arm: {why}",
            expected="6 revolute joints with UR's D-H shape (alpha 90, 0, 0, 90, -90, 0 deg)",
            fix="export --format urdf, or --onto the robot's own URDF",
        )


def design_origins(robot: RobotDescription) -> Array:
    """The design's joint origins in UR's layout (module docstring), (6, 4, 4) cm."""
    rows = [j.dh for j in robot.joints]
    a = np.r_[0.0, [r.a_cm for r in rows[:-1]]]
    alpha = np.radians(np.r_[0.0, [r.alpha_deg for r in rows[:-1]]])
    d = np.array([r.d_cm for r in rows])
    out: Array = trans_x(a) @ rot_x(alpha) @ trans_z(d)
    return out


def layout_urdf(origins: Array) -> bytes:
    """The xacro's kinematic chain (module docstring) with joint ``origins`` (6, 4, 4) cm;
    where its root sits in the design base, the same-robot check finds (``B``)."""
    lines = ['<robot name="ur">', '  <link name="base_link"/>']
    lines += [f'  <link name="{k}"/>' for k in LINKS]
    lines += [
        '  <joint name="base_link-base_link_inertia" type="fixed"><parent link="base_link"/>'
        f'<child link="{LINKS[0]}"/>{origin_element(BASE_INERTIA)}</joint>'
    ]
    for i, name in enumerate(JOINTS):
        lines.append(
            f'  <joint name="{name}" type="revolute"><parent link="{LINKS[i]}"/>'
            f'<child link="{LINKS[i + 1]}"/>{origin_element(origins[i])}<axis xyz="0 0 1"/>'
            '<limit lower="-6.283185307179586" upper="6.283185307179586" effort="0" '
            'velocity="0"/></joint>'
        )
    return ("\n".join([*lines, "</robot>"]) + "\n").encode()


def _num(v: float) -> str:
    """A double as YAML 1.1 (PyYAML, xacro's reader) reads back the same: ``1e-05`` would
    be a string there, so the mantissa gets its ``.0``."""
    s = repr(float(v))
    if "e" in s and "." not in s.split("e")[0]:
        s = s.replace("e", ".0e")
    return s


def yaml_text(origins: Array, tool: Array, digest: str, session: str) -> tuple[str, str]:
    """The file (``ur_calibration``'s layout) of calibrated ``origins`` (6, 4, 4) cm, the
    tool point ``tool`` (4, 4, cm, in ``wrist_3_link``), and its ``hash``."""
    xyz, rpy = xyz_rpy_from_transform(origins)
    hash_ = f"armsig_{digest[:16]}"
    lines = [
        f"# armsig: the signature of session {json.dumps(session)} for ur_description's xacro",
        "# (kinematics_parameters_file); metres and radians. The hash is armsig's, not the",
        "# controller's own calibration checksum: the UR driver warns that they differ.",
        "kinematics:",
    ]
    for k, name in enumerate(SECTIONS):
        values = (*(xyz[k] * M_PER_CM), *rpy[k])
        lines += [
            f"  {name}:",
            *(f"    {key}: {_num(v)}" for key, v in zip(KEYS, values, strict=True)),
        ]
    t = tool[:3, 3] * M_PER_CM
    lines += [
        f"  hash: {hash_}",
        "armsig:  # not read by the xacro",
        f"  session: {json.dumps(session)}",
        f"  signature_sha256: {digest}",
        "  tool_in_wrist_3_link:  # the measured tool point (m)",
        *(f"    {key}: {_num(v)}" for key, v in zip("xyz", t, strict=True)),
    ]
    return "\n".join(lines) + "\n", hash_


def origins_from_document(doc: dict[str, Any]) -> Array:
    """The six joint origins (6, 4, 4) cm a ``kinematics.yaml`` (as read back) states."""
    kin = doc["kinematics"]
    xyz = np.array([[kin[s][k] for k in KEYS[:3]] for s in SECTIONS], float) / M_PER_CM
    rpy = np.array([[kin[s][k] for k in KEYS[3:]] for s in SECTIONS], float)
    out: Array = transform_from_xyz_rpy(xyz, rpy)
    return out


def check_file(text: str, cal: Calibration, chain: Any, q: Array) -> tuple[float, float]:
    """The file as read back, through the xacro's formulas, against the calibrated links
    ``B X⁻¹ S_i(q) G_i`` of ``chain`` at readings ``q``; a bug above the export's check."""
    import yaml

    origins = origins_from_document(yaml.safe_load(text))
    S = link_frames(chain, q)
    T = np.broadcast_to(BASE_INERTIA, (len(q), 4, 4))
    got, want = [], []
    for i in range(6):
        T = T @ origins[i] @ rot_z(q[:, i])
        got.append(T)
        want.append(cal.BX @ S[:, i + 1] @ cal.G[i])
    dp, dr = pose_error(np.concatenate(want), np.concatenate(got))
    pos, rot = float(dp.max()) * M_PER_CM, float(dr.max())
    if not (pos <= CHECK_POSITION_M and rot <= CHECK_ORIENTATION_RAD):
        raise RuntimeError(f"the UR kinematics file does not reproduce the chain: {pos:.3e} m")
    return pos, rot


def export_ur_kinematics(
    session_dir: str | Path,
    out: str | Path | None = None,
    force: bool = False,
    accept_verdict: bool = False,
    over: str | Path | None = None,
) -> URKinematicsResult:
    """Write the session's signature as UR's ``kinematics.yaml`` (module docstring);
    ``out`` defaults to ``SESSION/export/ur_kinematics.yaml`` (armsig's folder,
    rewritten), an existing ``out`` needs ``force``."""
    sdir = Path(session_dir)
    if out is None:
        path = sdir / EXPORT_DIR / FILE
        check_writable(path.parent, "export folder", folder=True)
    else:
        path = check_new_file(out, "--out", force)
    doc = load_session_document(sdir / FILE_NAME)
    sig = signature_from_document(doc, str(sdir / FILE_NAME))
    check_ur(sig.robot)
    warning = verdict_gate(sig.verdict, str(sdir), accept_verdict)
    section = doc.get("nongeometric")
    if section and out is not None:
        check_new_file(sidecar_path(path), "sidecar", force)
    design = parse_vendor_urdf(layout_urdf(design_origins(sig.robot)), Path(FILE))
    best, loss = rigid_signature(sig, sdir, over)
    cal = calibrate(best, design, list(JOINTS))
    conv = cal.conventions
    if np.abs(conv.sign - 1).max() > 0 or np.abs(conv.offset).max() > 1e-9:
        raise RuntimeError(f"UR's layout reads joints otherwise: {conv.sign}, {conv.offset}")
    text, hash_ = yaml_text(cal.origins, cal.tool, str(doc[DIGEST_KEY]), sdir.name)
    q = random_readings(sig, CHECK_CONFIGURATIONS)
    pos, rot = check_file(text, cal, best.chain, q)
    full = in_frame(sig.chain, invert_transform(cal.BX))  # the signature's, base_link
    side_warning = write_sidecar(sig, section, path, q, "UR kinematics file", out is None,
                                 (full, "vendor-root", loss))  # fmt: skip
    write_text_atomic(path, text)
    return URKinematicsResult(
        path=str(path), joints=dict(zip((j.name for j in sig.robot.joints), JOINTS, strict=True)),
        tool_in_wrist_3_link_m=(cal.tool[:3, 3] * M_PER_CM).tolist(),
        base_link_from_design_base=cal.B.tolist(), configurations=CHECK_CONFIGURATIONS,
        max_position_error_m=pos, max_orientation_error_rad=rot, hash=hash_,
        verdict=None if sig.verdict is None else sig.verdict.status, verdict_warning=warning,
        sidecar=str(sidecar_path(path)) if section else None, sidecar_warning=side_warning,
        rigid_loss=loss if section else None,
    )  # fmt: skip
