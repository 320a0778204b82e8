"""`export --onto VENDOR.urdf` and the ROS-ready default URDF (issue 30 item 3), checked in
pinocchio: the calibrated vendor URDF's tool0 and tool point equal armsig's signature FK
(1e-9 m over 1,000 configurations), on a URDF of the session's own design (exact) and on
example-robot-data's UR10 with the real UR10 Series C signature; the vendor's XML is
unchanged but for the mapped joints' origins; another robot, unknown joints, a missing
file, an existing output are refused in one line.
"""

from __future__ import annotations

import importlib.metadata
import json
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from test_export import _check_urdf
from test_realdata import needs_ur10, ur10_c70  # noqa: F401  (the fixture, shared)
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.errors import ArmsigError
from pipeline.export import export, tool0_from_last
from pipeline.export.onto import OntoResult, export_onto
from pipeline.export.rigid import rigid_signature
from pipeline.export.urdf import origin_element
from pipeline.identify import identify
from pipeline.kinematics.chain import SerialChain, forward_kinematics, link_frames
from pipeline.kinematics.conventions import reading_conventions
from pipeline.kinematics.transforms import invert_transform, rot_x, rot_z, transform_from_xyz_rpy
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots import get_robot
from pipeline.robots.description import load_description
from pipeline.signature.file import Signature
from pipeline.signature.session import load_session_signature

REPO = Path(__file__).resolve().parents[1]
UR10 = REPO / "examples" / "ur10_ipa" / "ur10.toml"
CONFIGURATIONS = 1000
TOL_M = 1e-9  # the acceptance: 1e-9 m (and 1e-9 in rotation matrix entries)


def vendor_file(name: str) -> Path:
    """A URDF of example-robot-data's ur_description (skip when the package is absent)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (the test extra)")
    end = f"ur_description/urdf/{name}"
    return Path(str(next(dist.locate_file(f) for f in dist.files or [] if str(f).endswith(end))))


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Noiseless simulated SCARA (parallel axes, a prismatic quill) and UR10 pose set."""
    out = {}
    for name, opts in (
        ("scara", SimulationOptions(robot="scara", seed=1, noiseless=True, points=12, repeats=1)),
        ("ur10", SimulationOptions(robot=str(UR10), seed=1, noiseless=True, sensor="tracker",
                                   poses=40, sweeps=False)),
    ):  # fmt: skip
        d = tmp_path_factory.mktemp("onto") / name
        simulate_session(d, opts)
        identify(d, report=False)
        out[name] = d
    return out


def pin_frames(path: str | Path, q: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
    """Poses (m, 4, 4), metres, of frames ``names`` computed by pinocchio at ``q`` (rad)."""
    import pinocchio as pin

    model = pin.buildModelFromXML(Path(path).read_text())
    data = model.createData()
    out = {f: np.empty((len(q), 4, 4)) for f in names}
    for k, qk in enumerate(q):
        pin.framesForwardKinematics(model, data, qk)
        for f in names:
            out[f][k] = data.oMf[model.getFrameId(f)].homogeneous
    return out


def si(T: np.ndarray) -> np.ndarray:
    T = np.array(T, float)
    T[..., :3, 3] *= 0.01
    return T


def assert_same(T: np.ndarray, T_ref: np.ndarray, tol: float = TOL_M) -> float:
    dp = float(np.abs(T[:, :3, 3] - T_ref[:, :3, 3]).max())
    dr = float(np.abs(T[:, :3, :3] - T_ref[:, :3, :3]).max())
    assert dp <= tol and dr <= tol, (dp, dr)
    return dp


def readings(sig: Signature, seed: int = 30) -> np.ndarray:
    """1,000 readings within the limits, internal units (rad / cm)."""
    return sig.robot.random_configurations(CONFIGURATIONS, seed)


def urdf_q(sig: Signature, q: np.ndarray, r: OntoResult | None = None) -> np.ndarray:
    """URDF joint values (rad, m) of armsig readings ``q``; with ``r``, the vendor's
    ``sign · q + offset``."""
    if r is not None:
        off = np.where(sig.prismatic, r.vendor_offset, np.radians(r.vendor_offset))
        q = q * np.array(r.vendor_sign) + off
    return np.where(sig.prismatic, q * 0.01, q)


def check_onto(sig: Signature, r: OntoResult, default: Path) -> float:
    """The calibrated vendor URDF in pinocchio against armsig: its ``armsig_tool`` is the
    signature's tool point ``B · X⁻¹ · T(q)``, its ``tool0`` the default URDF's ``tool0``
    (the physical flange) moved by ``B``. Returns the largest position difference (m)."""
    q = readings(sig)
    B = si(np.array(r.vendor_root_from_design_base))
    cal = pin_frames(r.path, urdf_q(sig, q, r), ["armsig_tool", "tool0"])
    own = pin_frames(default, urdf_q(sig, q), ["tool0", "tool"])
    tool = si(invert_transform(sig.sensor_from_design_base) @ forward_kinematics(sig.chain, q))
    errs = [assert_same(cal["armsig_tool"], B @ tool), assert_same(own["tool"], tool)]
    return max(*errs, assert_same(cal["tool0"], B @ own["tool0"]))


# --- the reading conventions (the math of the same-robot check) ---------------------


def flipped(a: SerialChain, sign: np.ndarray, offset: np.ndarray) -> SerialChain:
    """Chain ``a`` read as ``v = sign · q + offset``: ``Rot(z, q − q0) = F Rot(z, v − c +
    s q0) F`` with ``F`` a half turn about x where ``s = −1``."""
    F = [rot_x(np.pi) if s < 0 else np.eye(4) for s in sign]
    links = [F[i] @ a.links[i] @ (F[i + 1] if i + 1 < len(F) else np.eye(4))
             for i in range(a.n_joints)]  # fmt: skip
    q0 = offset + sign * a.joint_offsets
    return SerialChain(np.stack(links), a.prismatic, a.base @ F[0], a.tool, q0)


def assert_same_robot(a: SerialChain, b: SerialChain, got, q: np.ndarray) -> None:
    """Every link frame of ``b`` at ``sign · q + offset`` is ``W ·`` (``a``'s at ``q``)
    ``· C_i`` with ``C_i`` constant: the definition of one robot read two ways."""
    Fa, Fb = link_frames(a, q)[:, :-1], link_frames(b, q * got.sign + got.offset)[:, :-1]
    C = invert_transform(got.world @ Fa) @ Fb  # (m, n + 1, 4, 4)
    assert np.abs(C - C[:1]).max() < 1e-9


@pytest.mark.parametrize("robot", ["puma560", "stanford", "scara", "ur10"])
def test_reading_conventions_are_recovered(robot: str) -> None:
    """Chains built to read ``sign · q + offset``: the conventions found make them the
    same robot (checked link by link), and are the ones built when no joint is reversed
    (where a half turn with the next joint reversed fits the same geometry, the found
    convention has as few reversed joints as the one built)."""
    desc = load_description(UR10) if robot == "ur10" else get_robot(robot)
    a = desc.design_chain()
    a = SerialChain(a.links, a.prismatic, a.base, a.tool, np.linspace(-0.3, 0.4, a.n_joints))
    rng = np.random.default_rng(3)
    names = [j.name for j in desc.joints]
    q = desc.random_configurations(50, 0)
    for k in range(6):
        sign = np.ones(a.n_joints) if k < 2 else rng.choice([-1.0, 1.0], a.n_joints)
        offset = np.where(a.prismatic, 0.0, rng.uniform(-3.0, 3.0, a.n_joints))
        sign[0], offset[0], offset[-1] = 1.0, 0.0, 0.0  # conventions of the frames
        b = flipped(a, sign, offset)
        Ta, Tb = forward_kinematics(a, q), forward_kinematics(b, q * sign + offset)
        assert np.abs(Ta - Tb).max() < 1e-11  # the construction: one robot, two readings
        got = reading_conventions(a, b, names)
        assert_same_robot(a, b, got, q)
        assert (got.sign < 0).sum() <= (sign < 0).sum()
        if k < 2:
            np.testing.assert_array_equal(got.sign, sign)
            np.testing.assert_allclose(got.offset, offset, rtol=0, atol=1e-12)


# --- (a) the session's own design as the vendor file -------------------------------


@pytest.mark.parametrize("robot", ["scara", "ur10"])
def test_onto_own_design_urdf(sessions, robot, tmp_path) -> None:
    d = sessions[robot]
    sig = load_session_signature(d / "signature.json")
    vendor = Path(export(d, "urdf", out=tmp_path / "vendor.urdf", design=True).path)
    default = Path(export(d, "urdf", out=tmp_path / "default.urdf").path)
    r = export_onto(d, vendor, out=tmp_path / "cal.urdf")
    assert r.joints == {j.name: j.name for j in sig.robot.joints}
    assert r.vendor_sign == [1.0] * sig.robot.n_joints and r.conventions_warning is None
    np.testing.assert_allclose(r.vendor_offset, 0.0, atol=1e-9)
    assert r.same_robot_m <= 1e-12 and r.max_position_error_m <= 1e-12
    np.testing.assert_allclose(r.vendor_root_from_design_base, np.eye(4), atol=1e-10)
    err = check_onto(sig, r, default)
    assert err <= 1e-12, err  # measured: ~3e-15 m


def test_onto_a_vendor_that_counts_otherwise(sessions, tmp_path) -> None:
    """A vendor file whose elbow turns about −z (reads −q) and whose wrist_1 origin is
    turned by 30 deg (reads q − 30 deg): both found, and the FK still exact."""
    d = sessions["ur10"]
    sig = load_session_signature(d / "signature.json")
    text = Path(export(d, "urdf", out=tmp_path / "v.urdf", design=True).path).read_text()
    blocks = re.split(r"(?=  <joint )", text)
    for k, b in enumerate(blocks):
        if '<joint name="elbow"' in b:
            blocks[k] = b.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 -1"/>')
        if '<joint name="wrist_1"' in b:
            m = re.search(r'<origin xyz="([^"]+)" rpy="([^"]+)"/>', b)
            assert m
            T = transform_from_xyz_rpy(np.array(m.group(1).split(), float) * 100,
                                       np.array(m.group(2).split(), float))  # fmt: skip
            blocks[k] = b.replace(m.group(0), origin_element(T @ rot_z(np.radians(30.0))))
    (tmp_path / "other.urdf").write_text("".join(blocks))
    default = Path(export(d, "urdf", out=tmp_path / "default.urdf").path)
    r = export_onto(d, tmp_path / "other.urdf", out=tmp_path / "cal.urdf")
    assert r.vendor_sign == [1.0, 1.0, -1.0, 1.0, 1.0, 1.0]
    np.testing.assert_allclose(r.vendor_offset, [0, 0, 0, -30.0, 0, 0], atol=1e-9)
    assert (
        r.conventions_warning and "elbow = -elbow, wrist_1 = wrist_1 -30" in r.conventions_warning
    )
    assert check_onto(sig, r, default) <= 1e-12


# --- (b) the real UR10 Series C signature onto example-robot-data's UR10 -------------


def _elements(path: Path) -> dict[str, list[bytes]]:
    """Every element under <robot> as canonical XML, by tag (joints without <origin>)."""
    root = ET.parse(path).getroot()
    out: dict[str, list[bytes]] = {}
    for e in root:
        if e.tag == "joint":
            for o in e.findall("origin"):
                e.remove(o)
        out.setdefault(e.tag, []).append(ET.canonicalize(ET.tostring(e)).encode())
    return out


@needs_ur10
def test_real_ur10_onto_example_robot_data(ur10_c70: Path, tmp_path: Path) -> None:  # noqa: F811
    vendor = vendor_file("ur10_robot.urdf")
    sig = load_session_signature(ur10_c70 / "signature.json")
    # issue 41: the real UR10 is a CHECK (accuracy limited by unmodelled error), which
    # export and --onto take without --accept-verdict (a warning); a FAIL is refused
    default = Path(export(ur10_c70, "urdf", out=tmp_path / "d.urdf").path)
    failed = shutil.copytree(ur10_c70, tmp_path / "failed")  # a requirement it misses
    identify(failed, report=False, overrides={"verdict": {"required_rms_mm": 0.3}})
    with pytest.raises(ArmsigError, match="verdict is FAIL"):  # issue 30 item 2, as export
        export_onto(failed, vendor, out=tmp_path / "f.urdf")
    assert not (tmp_path / "f.urdf").exists()
    r = export_onto(ur10_c70, vendor, out=tmp_path / "ur10.urdf")
    assert r.joints == {j.name: f"{j.name}_joint" for j in sig.robot.joints}
    assert r.vendor_sign == [1.0] * 6 and r.conventions_warning is None
    np.testing.assert_allclose(r.vendor_offset, 0.0, atol=1e-9)  # π/2 written 1.57079632679
    assert r.same_robot_m <= 1e-12, r.same_robot_m
    # the vendor's own file is the design model moved by B: its base_link turned 180 deg
    q = readings(sig)
    B = si(np.array(r.vendor_root_from_design_base))
    np.testing.assert_allclose(B[:3, :3], np.diag([-1.0, -1.0, 1.0]), atol=1e-12)
    design_tool0 = link_frames(sig.robot.design_chain(), q)[:, -2]
    own = pin_frames(vendor, urdf_q(sig, q), ["tool0"])["tool0"]
    assert_same(own, B @ si(design_tool0))
    # issue 43: the files hold the rigid chain nearest the whole signature (its terms and
    # its own rigid chain in the sidecar; tests/test_export_rigid.py)
    err = check_onto(rigid_signature(sig, ur10_c70)[0], r, default)
    assert err <= TOL_M, err  # measured 7e-12 m: the vendor's rounded π/2
    # meshes, inertias, limits, transmissions, gazebo tags: the same elements
    before, after = _elements(vendor), _elements(Path(r.path))
    tool = after["link"].pop(after["link"].index(b'<link name="armsig_tool"></link>'))
    assert tool and after["joint"].pop()  # the added tool link and its joint (the last)
    assert before == after
    moved = [r.origin_moves_mm[f"{j}_joint"] for j in ("shoulder_lift", "wrist_1")]
    assert all(0.1 < m < 2.0 for m in moved), r.origin_moves_mm  # a real robot, calibrated


# --- (c) refusals ------------------------------------------------------------------


def invoke(*args: str):
    return CliRunner().invoke(app, ["export", *args])


def assert_one_error(r, *fragments: str) -> None:
    assert r.exit_code == EXIT_REFUSED, (r.exit_code, r.output)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])


def test_refusals(sessions, tmp_path) -> None:
    d = str(sessions["ur10"])
    ur5, ur10 = vendor_file("ur5_robot.urdf"), vendor_file("ur10_robot.urdf")
    assert_one_error(invoke(d, "--onto", str(ur5)), "is not the robot ur10", "187 mm apart")
    assert_one_error(
        invoke(d, "--onto", str(ur10), "--joint-map", "elbow=knee"),
        "no moving joint for armsig's joint 'elbow'", "elbow_joint",
    )  # fmt: skip
    assert_one_error(invoke(d, "--onto", str(ur10), "--joint-map", "knee=elbow_joint"),
                     "unknown armsig joints ['knee']")  # fmt: skip
    assert_one_error(invoke(d, "--onto", str(tmp_path / "none.urdf")), "cannot read")
    copy = shutil.copy(ur10, tmp_path / "v.urdf")
    assert_one_error(invoke(d, "--onto", str(copy), "--out", str(copy), "--force"),
                     "is the vendor file itself")  # fmt: skip
    out = tmp_path / "cal.urdf"
    assert invoke(d, "--onto", str(copy), "--out", str(out)).exit_code == 0
    first = out.read_bytes()
    assert_one_error(invoke(d, "--onto", str(copy), "--out", str(out)), "already exists")
    assert out.read_bytes() == first and Path(copy).read_bytes() == ur10.read_bytes()
    assert_one_error(invoke(d, "--onto", str(copy), "--frame", "sensor"), "--onto")
    assert_one_error(invoke(d), "needs --format")


# --- the default URDF: root at the robot base, flange and tool0, limits -------------


@pytest.mark.parametrize("robot", ["scara", "ur10"])
def test_default_urdf_is_ros_ready(sessions, robot) -> None:
    d = sessions[robot]
    sig = load_session_signature(d / "signature.json")
    r = export(d, "urdf")
    assert r.frame == "design-base" and Path(r.path).name == "signature.urdf"
    root = ET.parse(r.path).getroot()
    children = {j.find("child").get("link") for j in root.iter("joint")}  # type: ignore[union-attr]
    links = [e.get("name") for e in root.iter("link")]
    assert [x for x in links if x not in children] == ["base_link"]
    assert {"flange", "tool0", "tool"} <= set(links)
    q = readings(sig)
    T = pin_frames(r.path, urdf_q(sig, q), ["flange", "tool0", "tool"])
    # tool0: the design flange on the signature, in the design base (the robot's base)
    X = sig.sensor_from_design_base
    last = link_frames(sig.chain, q)[:, -2]
    want = si(invert_transform(X) @ last @ tool0_from_last(sig, False))
    assert_same(T["tool0"], want)
    # REP-199: flange x and tool0 z are one direction, out of the flange; same origin
    np.testing.assert_allclose(T["flange"][:, :3, 0], T["tool0"][:, :3, 2], atol=1e-12)
    np.testing.assert_allclose(T["flange"][:, :3, 3], T["tool0"][:, :3, 3], atol=1e-12)
    # near the design model's flange in the design base, F_design(q): as near as the design
    # model is to the signature (the alignment's RMS misfit at the tool point; measured
    # max/RMS 1.5 on the simulated UR10 and SCARA, 1.8 on the real UR10 Series C)
    design = si(link_frames(sig.robot.design_chain(), q)[:, -2])
    gap = np.linalg.norm(T["tool0"][:, :3, 3] - design[:, :3, 3], axis=1).max()
    misfit = json.loads((d / "signature.json").read_text())["design_alignment"]["rms_misfit_cm"]
    assert gap <= 3 * misfit * 0.01, (gap, misfit)
    limits = [j.find("limit") for j in root.iter("joint") if j.get("type") != "fixed"]
    comments = Path(r.path).read_text().count("velocity and effort limits: not in")
    if robot == "ur10":  # examples/ur10_ipa/ur10.toml gives them: the vendor's (its source)
        vendor = [e for j in ET.parse(vendor_file("ur10_robot.urdf")).iter("joint")
                  if (e := j.find("limit")) is not None]  # fmt: skip
        assert len(vendor) == 6
        for key, rel in (("velocity", 1e-5), ("effort", 0.0)):  # deg/s written to 3 decimals
            want = [float(e.get(key)) for e in vendor]
            assert [float(e.get(key)) for e in limits] == pytest.approx(want, rel=rel)
        assert comments == 0
    else:
        assert all(float(e.get("velocity")) == 0 for e in limits) and comments == 4


def test_description_rates_are_checked(tmp_path) -> None:
    from pipeline.errors import RobotDescriptionError

    text = UR10.read_text()
    for bad, what in (("velocity_limit = -1.0", "must be positive"),
                      ("velocity_limit = 1e9", "out of bounds")):  # fmt: skip
        p = tmp_path / "r.toml"
        p.write_text(text.replace("velocity_limit = 123.759", bad, 1))
        with pytest.raises(RobotDescriptionError, match=what):
            load_description(p)


# --- (d) check_urdf on every export --------------------------------------------------


@pytest.mark.skipif(_check_urdf() is None, reason="check_urdf (liburdfdom-tools) not installed")
def test_check_urdf_accepts_every_export(sessions, tmp_path) -> None:
    d = sessions["ur10"]
    onto = export_onto(d, vendor_file("ur10_robot.urdf"), out=tmp_path / "c.urdf")
    paths = [export(d, "urdf").path, export(d, "urdf", frame="sensor").path,
             export(d, "urdf", design=True).path, onto.path]  # fmt: skip
    for p in paths:
        run = subprocess.run([str(_check_urdf()), p], capture_output=True, text=True)
        assert run.returncode == 0 and "Successfully Parsed XML" in run.stdout, run.stdout


# --- vendor files as vendors write them (issue 44) ----------------------------------


def _vendor_text(d: Path, tmp_path: Path) -> str:
    return Path(export(d, "urdf", out=tmp_path / "design.urdf", design=True).path).read_text()


def _origin_with_comment(text: str) -> str:
    """``text`` with its first joint's ``<origin .../>`` written as an element holding a
    comment that holds ``</origin>``."""
    m = re.search(r"<origin ([^>]*?)/>", text)
    assert m
    return text.replace(m.group(0), f"<origin {m.group(1)}><!-- was </origin> --></origin>", 1)


def _onto_text(d: Path, vendor: Path, out: Path) -> str:
    """The calibrated file of ``vendor`` as text (decoded as the vendor wrote it)."""
    export_onto(d, vendor, out=out)
    raw = out.read_bytes()
    for mark, codec in ((b"\xff\xfe", "utf-16-le"), (b"\xef\xbb\xbf", "utf-8")):
        if raw.startswith(mark):
            return raw[len(mark) :].decode(codec)
    return raw.decode("latin-1" if b"ISO-8859-1" in raw[:60] else "utf-8")


def test_vendor_files_in_other_encodings_and_with_comments_calibrate_alike(
    sessions, tmp_path
) -> None:
    """Issue 44: a UTF-8 byte-order mark, ``</origin>`` inside a comment, latin-1 link
    names, and UTF-16 were refused (and the message named the output file). Each now
    gives the plain file's calibration in the vendor's own encoding, every byte outside
    the edits the vendor's."""
    d = sessions["ur10"]
    text = _vendor_text(d, tmp_path)
    plain = tmp_path / "plain.urdf"
    plain.write_text(text)
    want = _onto_text(d, plain, tmp_path / "plain.cal.urdf")
    decl_end = text.index("?>") + 2 if text.startswith("<?xml") else 0
    body = text[decl_end:]

    def same(t: str) -> str:  # the text after the XML declaration, which names the encoding
        return t[t.index("?>") + 2 :] if t.startswith("<?xml") else t

    comment = "  <!-- an old <origin xyz='0 0 0'></origin> -->\n"
    cases = {
        "bom": (b"\xef\xbb\xbf" + text.encode(), str),
        "utf16": (
            b"\xff\xfe" + ('<?xml version="1.0" encoding="UTF-16"?>' + body).encode("utf-16-le"),
            str,
        ),
        "comment": (text.replace("</robot>", comment + "</robot>").encode(),
                    lambda t: t.replace(comment, "")),
        "comment_inside": (_origin_with_comment(text).encode(), str),
        "latin1": (
            ('<?xml version="1.0" encoding="ISO-8859-1"?>'
             + body.replace('"base_link"', '"basé"')).encode("latin-1"),
            lambda t: t.replace('"basé"', '"base_link"'),
        ),
    }  # fmt: skip
    for name, (data, back) in cases.items():
        vendor = tmp_path / f"{name}.urdf"
        vendor.write_bytes(data)
        got = _onto_text(d, vendor, tmp_path / f"{name}.cal.urdf")
        assert same(back(got)) == same(want), name


def test_a_vendor_tree_with_a_cycle_is_refused_and_a_mobile_base_is_read(
    sessions, tmp_path
) -> None:
    """Issue 44: a link with two parents was accepted (the last joint won); a planar or
    floating joint elsewhere in the file (a mobile base) was refused. A mobile base's
    arm is calibrated from the link below the base's joint."""
    d = sessions["ur10"]
    text = _vendor_text(d, tmp_path)
    root = re.search(r'<link name="([^"]+)"', text).group(1)
    extra = (f'  <link name="extra"/>\n  <joint name="loop" type="fixed">\n'
             f'    <parent link="extra"/>\n    <child link="{root}"/>\n  </joint>\n'
             f'  <joint name="back" type="fixed">\n    <parent link="tool0"/>\n'
             f'    <child link="extra"/>\n  </joint>\n')  # fmt: skip
    cyc = tmp_path / "cycle.urdf"
    cyc.write_text(text.replace("</robot>", extra + "</robot>"))
    with pytest.raises(ArmsigError, match="do not form one tree") as e:
        export_onto(d, cyc, out=tmp_path / "c.urdf")
    assert "\n" not in str(e.value) and not (tmp_path / "c.urdf").exists()
    two = tmp_path / "two.urdf"  # tool0 with a second parent
    two.write_text(text.replace("</robot>", '  <joint name="again" type="fixed">\n'
                                f'    <parent link="{root}"/>\n    <child link="tool0"/>\n'
                                "  </joint>\n</robot>"))  # fmt: skip
    with pytest.raises(ArmsigError, match=r"links with two parents \['tool0'\]"):
        export_onto(d, two, out=tmp_path / "t.urdf")
    sig = load_session_signature(d / "signature.json")
    default = Path(export(d, "urdf", out=tmp_path / "default.urdf").path)
    plain = tmp_path / "plain.urdf"
    plain.write_text(text)
    want = export_onto(d, plain, out=tmp_path / "plain.cal.urdf")
    for kind in ("floating", "planar"):
        base = (f'  <link name="world"/>\n  <joint name="mobile" type="{kind}">\n'
                f'    <parent link="world"/>\n    <child link="{root}"/>\n'
                '    <origin xyz="1 2 0" rpy="0 0 0.5"/>\n  </joint>\n')  # fmt: skip
        vendor = tmp_path / f"{kind}.urdf"
        vendor.write_text(text.replace("</robot>", base + "</robot>"))
        r = export_onto(d, vendor, out=tmp_path / f"{kind}.cal.urdf")
        np.testing.assert_allclose(
            r.vendor_root_from_design_base, want.vendor_root_from_design_base, atol=1e-12
        )
        assert f'type="{kind}"' in (tmp_path / f"{kind}.cal.urdf").read_text()
    assert check_onto(sig, want, default) <= 1e-12


def test_onto_a_device_a_pipe_a_folder_or_a_huge_file_is_one_line(
    sessions, tmp_path, monkeypatch
) -> None:
    """Issue 44: ``export --onto /dev/zero`` read until a MemoryError (exit 70)."""
    import os

    import pipeline.export.vendor as vendor

    d = str(sessions["ur10"])
    fifo = tmp_path / "pipe.urdf"
    os.mkfifo(fifo)  # opening it would block until a writer came
    for path in ("/dev/zero", str(fifo), str(tmp_path)):
        assert_one_error(invoke(d, "--onto", path), f"the vendor URDF {path} is not a regular")
    monkeypatch.setattr(vendor, "MAX_URDF_BYTES", 2**20)
    big = tmp_path / "big.urdf"
    big.write_bytes(b"<robot name='x'>" + b" " * 2**20 + b"</robot>")
    assert_one_error(invoke(d, "--onto", str(big)), "big.urdf is over 1 MiB")
