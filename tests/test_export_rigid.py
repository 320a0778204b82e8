"""Issue 43, item 1: the best a rigid file can hold, stated.

An export of a signature with non-geometric terms holds the rigid chain nearest the whole
signature at the tool point (least squares over readings within the joint limits, or the
``--over`` file's), states what it loses, and keeps the whole signature in the sidecar. A
rigid signature exports exactly as before. On the real UR10 (Series C signature, Series
B's poses) the calibrated vendor URDF is evaluated in pinocchio.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from doc_quotes import assert_quoted
from test_export import compliant  # noqa: F401  (the fixture, shared)
from test_export_onto import pin_frames, urdf_q, vendor_file
from test_realdata import UR10_DATA, UR10_EXAMPLE, needs_ur10, ur10_c70  # noqa: F401
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.export import export
from pipeline.export.documents import chain_from_document
from pipeline.export.onto import export_onto
from pipeline.export.rigid import FIT_CONFIGURATIONS, fit_readings, rigid_signature
from pipeline.kinematics.chain import SerialChain, forward_kinematics
from pipeline.kinematics.transforms import invert_transform, transform_from_xyz_rpy
from pipeline.refine.rigid import best_rigid_chain
from pipeline.signature.session import load_session_signature

#: Perturbation of a chain constant (rad, cm): its quadratic rise of the squared loss,
#: ~1e-6 relative here, is far above the solver's 1e-15 and round-off; small enough that
#: the loss is quadratic in it.
STEP = 1e-3


def tool_points(chain: SerialChain, q: np.ndarray) -> np.ndarray:
    return forward_kinematics(chain, q)[:, :3, 3]


def rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def perturbed(chain: SerialChain, where: int, xyz_rpy: np.ndarray) -> SerialChain:
    """``chain`` with one constant moved by ``Δ = (xyz, rpy)``: the base (``where`` −1),
    link ``where``'s ``K̄`` or the tool (``where`` n), as ``T · Δ``."""
    D = transform_from_xyz_rpy(xyz_rpy[:3], xyz_rpy[3:])
    links, base, tool = chain.links.copy(), chain.base, chain.tool
    if where < 0:
        base = base @ D
    elif where == chain.n_joints:
        tool = tool @ D
    else:
        links[where] = links[where] @ D
    return SerialChain(links, chain.prismatic, base, tool, chain.joint_offsets)


def test_the_exported_chain_is_the_least_squares_optimum(compliant, tmp_path) -> None:  # noqa: F811
    """The chain JSON as written, read back: its RMS loss at the fit's readings is the one
    stated, below the signature's rigid part's, and no move of any of its constants (base,
    each link, tool; 6 directions each, and 50 random combinations) lowers it."""
    d = compliant["terms"]
    r = export(d, "json", out=tmp_path / "r.chain.json", frame="sensor")
    sig = load_session_signature(d / "signature.json")
    assert sig.nongeometric is not None and r.rigid_loss is not None
    chain = chain_from_document(json.loads(Path(r.path).read_text()), sig.prismatic)
    q = fit_readings(sig)
    assert len(q) == r.rigid_loss.configurations == FIT_CONFIGURATIONS
    full = tool_points(sig.chain, sig.nongeometric.effective(q))
    best = rms(tool_points(chain, q), full)
    assert best * 10 == pytest.approx(r.rigid_loss.rms_mm, rel=1e-9)
    assert r.rigid_loss.rms_mm < 0.8 * r.rigid_loss.signature_rigid_rms_mm  # measured 0.71
    assert r.rigid_loss.held == ()  # the PUMA's tool point sees every parameter
    n = sig.robot.n_joints
    rng = np.random.default_rng(43)
    moves = [(w, s * STEP * e) for w in range(-1, n + 1) for e in np.eye(6) for s in (1, -1)]
    moves += [(int(rng.integers(-1, n + 1)), STEP * rng.standard_normal(6)) for _ in range(50)]
    worse = [rms(tool_points(perturbed(chain, w, v), q), full) - best for w, v in moves]
    assert min(worse) >= -1e-12 * best, min(worse)
    assert max(worse) > 1e-7 * best  # the test can fail: a move does change the loss


def test_a_rigid_signature_exports_exactly_as_before(compliant, tmp_path) -> None:  # noqa: F811
    """No terms: the signature itself, untouched (bit for bit: the JSON holds its very
    doubles). Terms that are all zero: the fit gives the signature's chain back (1e-12)."""
    d = compliant["rigid"]
    sig = load_session_signature(d / "signature.json")
    best, loss = rigid_signature(sig, d)
    assert best is sig and loss is None
    r = export(d, "json", out=tmp_path / "r.chain.json", frame="sensor")
    doc = json.loads(Path(r.path).read_text())
    assert doc["links"] == sig.chain.links.tolist() and doc["base"] == sig.chain.base.tolist()
    assert doc["tool"] == sig.chain.tool.tolist() and r.rigid_loss is None
    ng = load_session_signature(compliant["terms"] / "signature.json").nongeometric
    assert ng is not None
    zero = replace(ng, coefficients=np.zeros_like(ng.coefficients))
    q = fit_readings(sig)
    fit = best_rigid_chain(sig.chain, zero, q)
    assert fit.max_cm <= 1e-12
    for a, b in ((fit.chain.links, sig.chain.links), (fit.chain.base, sig.chain.base),
                 (fit.chain.tool, sig.chain.tool)):  # fmt: skip
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_the_sidecar_holds_the_whole_signature(compliant, tmp_path) -> None:  # noqa: F811
    """The sidecar's terms on its own design chain, applied to its own signature chain,
    give the whole signature in the export's frame (the URDF's: the design base); its
    loss is the export's."""
    from pipeline.export.sidecar import nongeometric_from_sidecar, signature_from_sidecar

    d = compliant["terms"]
    r = export(d, "urdf", out=tmp_path / "r.urdf")
    sig = load_session_signature(d / "signature.json")
    assert sig.nongeometric is not None and r.rigid_loss is not None
    doc = json.loads(Path(str(r.sidecar)).read_text())
    assert doc["signature_frame"] == "design-base"
    assert doc["rigid_loss"]["rms_mm"] == r.rigid_loss.rms_mm
    q = sig.robot.random_configurations(1000, 7)
    ng = nongeometric_from_sidecar(doc, sig.prismatic)
    mine = forward_kinematics(signature_from_sidecar(doc, sig.prismatic), ng.effective(q))
    want = invert_transform(sig.sensor_from_design_base) @ forward_kinematics(
        sig.chain, sig.nongeometric.effective(q)
    )
    np.testing.assert_allclose(mine, want, rtol=0, atol=1e-9)


def _q_csv(path: Path, q_deg: np.ndarray) -> Path:
    head = ",".join(f"q{i + 1}_deg" for i in range(q_deg.shape[1]))
    path.write_text(head + "\n" + "".join(",".join(map(repr, r)) + "\n" for r in q_deg.tolist()))
    return path


def test_over_a_file_of_configurations(compliant, tmp_path) -> None:  # noqa: F811
    """``--over``: the fit and the stated loss over the file's configurations (a smaller
    loss there than over the joint limits: half the ranges); too few rows or a missing
    column are one line, exit 1, nothing written."""
    d = compliant["terms"]
    sig = load_session_signature(d / "signature.json")
    lim = sig.robot.limits
    q = np.random.default_rng(5).uniform(lim[:, 0] / 2, lim[:, 1] / 2, (300, 6))
    over = _q_csv(tmp_path / "work.csv", q)
    r = export(d, "urdf", out=tmp_path / "w.urdf", over=over)
    assert r.rigid_loss is not None and r.rigid_loss.configurations == 300
    assert "over 300 configurations of work.csv" in str(r.sidecar_warning)
    wide = export(d, "urdf", out=tmp_path / "l.urdf").rigid_loss
    assert wide is not None and r.rigid_loss.rms_mm < wide.rms_mm
    few = _q_csv(tmp_path / "few.csv", q[:5])
    bad = tmp_path / "bad.csv"
    bad.write_text("q1_deg,q2_deg\n1,2\n")
    for f, says in ((few, "5 configurations cannot fix the rigid chain"),
                    (bad, "missing column(s) q3_deg")):  # fmt: skip
        out = tmp_path / "x.urdf"
        res = CliRunner().invoke(app, ["export", str(d), "--format", "urdf", "--out", str(out),
                                       "--over", str(f)])  # fmt: skip
        lines = res.stderr.splitlines()
        assert res.exit_code == EXIT_REFUSED and len(lines) == 1 and says in lines[0], res.stderr
        assert not out.exists() and not out.with_suffix(".nongeometric.json").exists()


# --- the real UR10: the Series C signature onto example-robot-data's UR10, Series B ----


def _series_b(sig) -> tuple[np.ndarray, np.ndarray]:
    """Series B's readings (deg) and measured T-Mac points (cm)."""
    from pipeline.evaluate.validate import _as_poses
    from pipeline.importers import parse_foreign
    from pipeline.importers.mapping import load_map

    imap = _as_poses(load_map(UR10_EXAMPLE / "series_b.toml"))
    path = UR10_DATA / "Series_B" / "measurements_joint_configurations.csv"
    rows, _ = parse_foreign(path, "table", sig.robot, imap)
    return sig.robot.joints_from_readings(rows.q), rows.targets["tmac"]


@needs_ur10
def test_real_ur10_series_b_through_the_calibrated_vendor_urdf(ur10_c70, tmp_path) -> None:  # noqa: F811
    """The calibrated vendor URDF in pinocchio against Series B, base registered (as
    ``validate`` registers): armsig's whole signature 0.588 mm; the signature's rigid part
    (what --onto wrote before issue 43) 0.835 mm; the nearest rigid chain over the joint
    limits 0.829 mm; over Series B's own configurations (``--over``, the readings only)
    0.601 mm."""
    from pipeline.evaluation.validation import error_distances, model_points

    vendor = vendor_file("ur10_robot.urdf")
    sig = load_session_signature(ur10_c70 / "signature.json")
    q_deg, measured = _series_b(sig)
    qi = np.radians(q_deg)

    def registered_mm(points_cm: np.ndarray) -> float:
        reg = error_distances(points_cm, measured)[1]
        assert reg is not None
        return float(np.sqrt(np.mean(reg**2))) * 10

    whole = registered_mm(model_points(sig.chain, q_deg, sig.prismatic, sig.nongeometric))
    part = registered_mm(model_points(sig.chain, q_deg, sig.prismatic))
    got = {}
    for name, over in (("limits", None), ("b", _q_csv(tmp_path / "b.csv", q_deg))):
        r = export_onto(ur10_c70, vendor, out=tmp_path / f"{name}.urdf", over=over)
        assert r.rigid_loss is not None and r.rigid_loss.held == ("joint6.rx", "joint6.ry")
        T = pin_frames(r.path, urdf_q(sig, qi, r), ["armsig_tool"])["armsig_tool"]
        got[name] = registered_mm(T[:, :3, 3] * 100)
        if over is None:  # the warning docs/export.md shows
            assert_quoted("docs/export.md", r.rigid_loss.text("the URDF"))
    assert round(whole, 3) == 0.588 and round(part, 3) == 0.835, (whole, part)
    assert round(got["limits"], 3) == 0.829 and round(got["b"], 3) == 0.601, got
    rows = {
        "whole signature (`validate`)": whole,
        "(`--over`, readings only)": got["b"],
        "joint limits (the default)": got["limits"],
        "rigid part": part,
    }
    for what, v in rows.items():
        assert_quoted("docs/export.md", f"{what} | {v:.3f} mm |")
