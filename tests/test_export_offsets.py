"""Issue 43, item 4 (second choice): ``export --onto VENDOR.urdf --offsets-only``, the
signature as robot_calibration's ``<calibration rising>`` joint offsets.

A simulated UR10 whose only errors are its encoder offsets: the file, read by pinocchio
at the readings plus the offsets read from it, is the signature to 1e-9 m (base
registered), the stated loss ~0; the vendor's other bytes are unchanged; a vendor file
with offsets already is refused in one line. The real UR10 (Series C signature): the loss
stated, and Series B through the file in pinocchio.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from doc_quotes import assert_quoted
from test_export_onto import vendor_file
from test_export_rigid import _series_b
from test_realdata import needs_ur10, ur10_c70  # noqa: F401
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.evaluation.validation import error_distances
from pipeline.export import export
from pipeline.export.offsets import export_offsets
from pipeline.export.rigid import fit_readings
from pipeline.identify import identify
from pipeline.kinematics.chain import forward_kinematics
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.rig.true_robot import ErrorSigmas
from pipeline.signature.session import load_session_signature

UR10 = Path(__file__).resolve().parents[1] / "examples" / "ur10_ipa" / "ur10.toml"


@pytest.fixture(scope="module")
def offsets_only(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A noiseless UR10 pose set whose true robot is the design but for 0.3° (σ) encoder
    offsets."""
    d = tmp_path_factory.mktemp("offsets") / "ur10"
    opts = SimulationOptions(robot=str(UR10), seed=3, noiseless=True, sensor="tracker",
                             poses=40, sweeps=False, sigmas=ErrorSigmas(0.0, 0.0, 0.3))  # fmt: skip
    simulate_session(d, opts)
    identify(d, report=False)
    return d


def pin_tool_points(path: Path, q: np.ndarray) -> np.ndarray:
    """``armsig_tool`` (m, 3) in cm by pinocchio at readings ``q`` (rad) plus each joint's
    ``<calibration rising>`` as the file states it (robot_calibration's rule)."""
    import pinocchio as pin

    joints = ET.parse(path).getroot().iter("joint")
    rising = {j.get("name"): float(c.get("rising", "0")) for j in joints
              for c in j.iter("calibration")}  # fmt: skip
    model = pin.buildModelFromXML(path.read_text())
    data = model.createData()
    off = np.array([rising.get(n, 0.0) for n in list(model.names)[1:]])
    frame = model.getFrameId("armsig_tool")
    out = np.empty((len(q), 3))
    for k, qk in enumerate(q):
        pin.framesForwardKinematics(model, data, qk + off)
        out[k] = data.oMf[frame].translation * 100
    return out


def registered_rms(points: np.ndarray, measured: np.ndarray) -> float:
    reg = error_distances(points, measured)[1]
    assert reg is not None
    return float(np.sqrt(np.mean(reg**2)))


def test_an_offsets_only_robot_is_its_offsets(offsets_only: Path, tmp_path: Path) -> None:
    d = offsets_only
    sig = load_session_signature(d / "signature.json")
    vendor = Path(export(d, "urdf", out=tmp_path / "vendor.urdf", design=True).path)
    r = export_offsets(d, vendor, out=tmp_path / "off.urdf")
    assert r.rms_mm < 1e-6 and r.max_mm < 1e-6, r  # measured: round-off
    assert r.held == ["shoulder_pan"] and r.offsets["shoulder_pan"] == 0.0
    assert max(abs(v) for v in r.offsets.values()) > 0.05  # deg: offsets that matter
    q = fit_readings(sig)[:1000]
    want = forward_kinematics(sig.chain, q)[:, :3, 3]
    assert registered_rms(pin_tool_points(Path(r.path), q), want) < 1e-7  # cm: 1e-9 m
    # the vendor's bytes but for the calibration tags and the armsig_tool link
    text = Path(r.path).read_text()
    assert text.count("<calibration rising=") == 5
    stripped = re.sub(r'  <calibration rising="[^"]*"/>\n  ', "", text)
    stripped = re.sub(r"  <!-- armsig: the measured tool point.*?</joint>\n", "", stripped,
                      flags=re.S)  # fmt: skip
    assert stripped == vendor.read_text()
    # a UTF-16 vendor file (issue 44) is written back in UTF-16, the same file otherwise
    wide = tmp_path / "wide.urdf"
    wide.write_bytes(b"\xff\xfe" + vendor.read_text().encode("utf-16-le"))
    r16 = export_offsets(d, wide, out=tmp_path / "off16.urdf")
    raw = Path(r16.path).read_bytes()
    assert raw.startswith(b"\xff\xfe") and raw[2:].decode("utf-16-le") == text


def test_a_vendor_file_with_offsets_is_refused(offsets_only: Path, tmp_path: Path) -> None:
    vendor = Path(export(offsets_only, "urdf", out=tmp_path / "v.urdf", design=True).path)
    text = vendor.read_text().replace('<joint name="elbow" type="revolute">',
                                      '<joint name="elbow" type="revolute"><calibration '
                                      'rising="0.01"/>')  # fmt: skip
    (tmp_path / "c.urdf").write_text(text)
    out = tmp_path / "o.urdf"
    res = CliRunner().invoke(app, ["export", str(offsets_only), "--onto", str(tmp_path / "c.urdf"),
                                   "--offsets-only", "--out", str(out)])  # fmt: skip
    lines = res.stderr.splitlines()
    assert res.exit_code == EXIT_REFUSED and len(lines) == 1, res.output
    assert "joint 'elbow' holds a calibration offset already" in lines[0]
    assert not out.exists()
    res = CliRunner().invoke(app, ["export", str(offsets_only), "--format", "urdf",
                                   "--offsets-only"])  # fmt: skip
    assert res.exit_code == EXIT_REFUSED and "goes with --onto" in res.stderr


@needs_ur10
def test_real_ur10_offsets_only(ur10_c70: Path, tmp_path: Path) -> None:  # noqa: F811
    """The UR10's signature is not offsets: the file loses 1.38 mm RMS over the joint
    limits, and Series B through it in pinocchio is 1.085 mm registered, the design's own
    (validate's baseline 1.085 mm): offsets alone gain nothing on this arm."""
    sig = load_session_signature(ur10_c70 / "signature.json")
    r = export_offsets(ur10_c70, vendor_file("ur10_robot.urdf"), out=tmp_path / "o.urdf")
    assert r.held == ["shoulder_pan_joint", "wrist_3_joint"]  # joint 6: the probe on its axis
    q_deg, measured = _series_b(sig)
    b = registered_rms(pin_tool_points(Path(r.path), np.radians(q_deg)), measured) * 10
    assert_quoted("docs/export.md", r.text())
    assert_quoted("docs/export.md", f"Series B through it in pinocchio: {b:.3f} mm")
