"""Issue 43, item 2: ``export --format ur-kinematics``, UR's ``kinematics.yaml``.

The file is read back with PyYAML (xacro's reader) and evaluated here through the
``ur_description`` xacro's own formulas (Universal_Robots_ROS2_Description
``urdf/ur_macro.xacro``: ``base_link`` → rpy ``0 0 π`` → six joints whose ``<origin>`` are
the file's ``x y z roll pitch yaw``, axis z → ``wrist_3_link`` → ``flange`` rpy
``0 −π/2 −π/2`` → ``tool0`` rpy ``π/2 0 π/2``), written independently with scipy's
rotations: its tool point equals armsig's rigid signature FK to 1e-9 m at 1,000
configurations (the real UR10 Series C signature), its ``tool0`` the ``--onto`` calibrated
example-robot-data UR10's in pinocchio. The layout is UR's published default file (UR30);
a non-UR chain is refused in one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from test_export import compliant  # noqa: F401  (the fixture, shared)
from test_export_onto import pin_frames, vendor_file
from test_realdata import needs_ur10, ur10_c70  # noqa: F401
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.export.onto import export_onto
from pipeline.export.rigid import rigid_signature
from pipeline.export.ur_kinematics import SECTIONS, _num, design_origins, export_ur_kinematics
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.transforms import invert_transform
from pipeline.robots.description import description_from_dict
from pipeline.signature.session import load_session_signature

TOL_M = 1e-9  # the acceptance


def origin(xyz, rpy) -> np.ndarray:
    """A URDF ``<origin>``: ``Trans(xyz) · Rz(yaw) Ry(pitch) Rx(roll)`` (extrinsic x-y-z)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    T[:3, 3] = xyz
    return T


def turn(q: np.ndarray) -> np.ndarray:
    """``Rz(q)`` (m, 4, 4): a revolute joint about z."""
    return np.stack([origin([0, 0, 0], [0, 0, v]) for v in q])


def xacro_frames(doc: dict, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``wrist_3_link`` and ``tool0`` in ``base_link`` (m) at UR readings ``q`` (rad)."""
    T = np.broadcast_to(origin([0, 0, 0], [0, 0, np.pi]), (len(q), 4, 4))
    for i, s in enumerate(SECTIONS):
        k = doc["kinematics"][s]
        T = T @ origin([k["x"], k["y"], k["z"]], [k["roll"], k["pitch"], k["yaw"]]) @ turn(q[:, i])
    tool0 = (
        T
        @ origin([0, 0, 0], [0, -np.pi / 2, -np.pi / 2])
        @ origin([0, 0, 0], [np.pi / 2, 0, np.pi / 2])
    )
    return T, tool0


@needs_ur10
def test_real_ur10_kinematics_yaml_through_the_xacro_formulas(ur10_c70, tmp_path) -> None:  # noqa: F811
    sig = load_session_signature(ur10_c70 / "signature.json")
    r = export_ur_kinematics(ur10_c70, out=tmp_path / "k.yaml")
    text = Path(r.path).read_text()
    doc = yaml.safe_load(text)
    assert list(doc["kinematics"]) == [*SECTIONS, "hash"]
    assert all(
        set(doc["kinematics"][s]) == {"x", "y", "z", "roll", "pitch", "yaw"} for s in SECTIONS
    )
    assert all(isinstance(v, float) for s in SECTIONS for v in doc["kinematics"][s].values())
    assert doc["kinematics"]["hash"] == r.hash and r.hash.startswith("armsig_")
    q = sig.robot.random_configurations(1000, 43)  # UR's readings are the description's
    wrist_3, tool0 = xacro_frames(doc, q)
    t = doc["armsig"]["tool_in_wrist_3_link"]
    point = wrist_3[:, :3, :3] @ np.array([t["x"], t["y"], t["z"]]) + wrist_3[:, :3, 3]
    # armsig's rigid signature (the Series C signature has compliance: the rigid chain
    # nearest it, as every rigid export holds) in base_link: B · X⁻¹ · T(q), metres
    best = rigid_signature(sig, ur10_c70)[0]
    B = np.array(r.base_link_from_design_base)
    T = B @ invert_transform(sig.sensor_from_design_base) @ forward_kinematics(best.chain, q)
    err = np.abs(point - T[:, :3, 3] * 0.01).max()
    assert err <= TOL_M, err  # measured 3.8e-15 m
    # tool0: the --onto calibrated example-robot-data UR10's in pinocchio (the same frames)
    onto = export_onto(ur10_c70, vendor_file("ur10_robot.urdf"), out=tmp_path / "o.urdf")
    assert np.allclose(np.array(onto.vendor_root_from_design_base), B, rtol=0, atol=1e-12)
    pin_tool0 = pin_frames(onto.path, q, ["tool0"])["tool0"]
    assert np.abs(pin_tool0[:, :3, 3] - tool0[:, :3, 3]).max() <= TOL_M  # measured 7e-12
    assert np.abs(pin_tool0[:, :3, :3] - tool0[:, :3, :3]).max() <= TOL_M
    assert r.sidecar is not None and r.rigid_loss is not None  # the whole signature beside


#: UR's published default kinematics of the UR30 (Universal_Robots_ROS2_Description
#: config/ur30/default_kinematics.yaml), and its D-H (physical_parameters.yaml), cm.
UR30_DEFAULT = {
    "shoulder": ([0, 0, 0.2363], [0, 0, 0]),
    "upper_arm": ([0, 0, 0], [1.570796327, 0, 0]),
    "forearm": ([-0.637, 0, 0], [0, 0, 0]),
    "wrist_1": ([-0.5037, 0, 0.201], [0, 0, 0]),
    "wrist_2": ([0, -0.1593, 0], [1.570796327, 0, 0]),
    "wrist_3": ([0, 0.1543, -3.1647459019915597e-11], [1.5707963265897931, np.pi, np.pi]),
}
UR30_DH = [(23.63, 0.0, 90.0), (0.0, -63.7, 0.0), (0.0, -50.37, 0.0), (20.1, 0.0, 90.0),
           (15.93, 0.0, -90.0), (15.43, 0.0, 0.0)]  # fmt: skip


def _ur_description(dh: list[tuple[float, float, float]], name: str = "ur30") -> dict:
    names = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
    return {
        "name": name,
        "joints": [
            {
                "name": n,
                "type": "revolute",
                "limits": [-360.0, 360.0],
                "encoder_resolution": 1e-4,
                "dh": {"theta_deg": 0.0, "d_cm": d, "a_cm": a, "alpha_deg": al},
            }
            for n, (d, a, al) in zip(names, dh, strict=True)
        ],  # fmt: skip
    }


def test_the_layout_is_urs_default_file() -> None:
    """The design in UR's layout (origin ``Tx(a_{i−1}) Rx(α_{i−1}) Tz(d_i)``) is UR's own
    default file of the UR30, to its rounding of π/2 (1.570796327: 2e-10)."""
    robot = description_from_dict(_ur_description(UR30_DH), source="test")
    mine = design_origins(robot)
    for i, s in enumerate(SECTIONS):
        xyz, rpy = UR30_DEFAULT[s]
        want = origin(np.array(xyz) * 100, rpy)
        np.testing.assert_allclose(mine[i], want, rtol=0, atol=1e-8)


def test_yaml_numbers_read_back_exactly() -> None:
    """Every double as the file writes it reads back the same through PyYAML (YAML 1.1
    reads ``1e-05`` as a string: the writer gives ``1.0e-05``)."""
    rng = np.random.default_rng(0)
    values = [
        0.0,
        -0.0,
        1e-5,
        -3e-12,
        1e22,
        0.1,
        np.pi,
        *(rng.standard_normal(200) * 10.0 ** rng.integers(-15, 5, 200)),
    ]
    for v in values:
        back = yaml.safe_load(f"v: {_num(v)}")["v"]
        assert isinstance(back, float) and back == v, (v, _num(v))


def test_a_non_ur_chain_is_refused_in_one_line(compliant, tmp_path) -> None:  # noqa: F811
    out = tmp_path / "k.yaml"
    res = CliRunner().invoke(app, ["export", str(compliant["terms"]), "--format",
                                   "ur-kinematics", "--out", str(out)])  # fmt: skip
    lines = res.stderr.splitlines()
    assert res.exit_code == EXIT_REFUSED and len(lines) == 1, res.output
    assert "robot puma560 is not a Universal Robots arm: alpha" in lines[0], lines[0]
    assert not out.exists()
    res = CliRunner().invoke(app, ["export", str(compliant["terms"]), "--format",
                                   "ur-kinematics", "--frame", "sensor"])  # fmt: skip
    assert res.exit_code == EXIT_REFUSED and "ur-kinematics writes" in res.stderr


@pytest.fixture(scope="module")
def ur10_sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from pipeline.identify import identify
    from pipeline.rig.simulate import SimulationOptions, simulate_session

    d = tmp_path_factory.mktemp("urk") / "ur10"
    ur10 = str(Path(__file__).resolve().parents[1] / "examples" / "ur10_ipa" / "ur10.toml")
    simulate_session(d, SimulationOptions(robot=ur10, seed=2, noiseless=True, sensor="tracker",
                                          poses=40, sweeps=False))  # fmt: skip
    identify(d, report=False)
    return d


def test_cli_writes_armsigs_folder_and_keeps_a_users_file(ur10_sim, tmp_path) -> None:
    """Default path in SESSION/export/, rewritten; an existing --out needs --force; the
    simulated UR10's file reproduces its signature through the xacro formulas."""
    r = CliRunner().invoke(app, ["export", str(ur10_sim), "--format", "ur-kinematics"])
    assert r.exit_code == 0, r.output
    path = ur10_sim / "export" / "ur_kinematics.yaml"
    assert f"wrote {path}" in r.stdout and path.is_file()
    doc = yaml.safe_load(path.read_text())
    sig = load_session_signature(ur10_sim / "signature.json")
    q = sig.robot.random_configurations(1000, 1)
    wrist_3, _ = xacro_frames(doc, q)
    t = doc["armsig"]["tool_in_wrist_3_link"]
    point = wrist_3[:, :3, :3] @ np.array([t["x"], t["y"], t["z"]]) + wrist_3[:, :3, 3]
    res = export_ur_kinematics(ur10_sim, out=tmp_path / "a.yaml")
    B = np.array(res.base_link_from_design_base)
    best = rigid_signature(sig, ur10_sim)[0]
    assert sig.nongeometric is None and best is sig  # a rigid signature: its own FK
    T = B @ invert_transform(sig.sensor_from_design_base) @ forward_kinematics(best.chain, q)
    assert np.abs(point - T[:, :3, 3] * 0.01).max() <= TOL_M
    mine = tmp_path / "mine.yaml"
    mine.write_text("the user's file")
    r = CliRunner().invoke(app, ["export", str(ur10_sim), "--format", "ur-kinematics", "--out",
                                 str(mine)])  # fmt: skip
    assert r.exit_code == EXIT_REFUSED and "already exists" in r.stderr
    assert mine.read_text() == "the user's file"
