"""A camera session's signature and everything downstream (issue 39): ``signature.json``
(the chain, the lens with σ, both hand-eye transforms), uncertainty, held-out images,
the verdict, the report, the URDF's camera frames, ``camera_info``, ``armsig.load``,
``fleet`` and ``plan``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import ArmsigError
from pipeline.kinematics.chain import forward_kinematics
from pipeline.kinematics.transforms import invert_transform, transform_from_xyz_rpy
from pipeline.refine.camera_verdict import PixelHoldout, judge_camera, pixel_reasons
from pipeline.refine.verdict import CHECK, FAIL, PASS, Evidence, Thresholds
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.sensor.camera import project
from pipeline.sensor.target import target_from_dict
from pipeline.signature.file import load_signature
from pipeline.stages.recording import read_recording
from pipeline.stages.tables import read_table
from pipeline.sweeps import POSES_SWEEP
from pipeline.units import joints_to_internal

ROOT = Path(__file__).resolve().parents[1]
UR10 = str(ROOT / "examples" / "ur10_ipa" / "ur10.toml")


def _identified(tmp: Path, setup: str, robot: str = "puma560", poses: int = 12, **kw) -> Path:
    from pipeline.identify import identify

    d = tmp / setup
    opts = SimulationOptions(robot=robot, sensor="camera", setup=setup, poses=poses, **kw)
    simulate_session(d, opts)
    identify(d, report=False)
    return d


def _reprojected(d: Path) -> tuple[np.ndarray, np.ndarray]:
    """The detected pixels (D, 2) and the pixels the signature file alone predicts (D, 2):
    its chain at each image's readings, its lens, the recorded target."""
    sig = load_signature(d / "signature.json")
    rec = read_recording(d / "recording.mcap")
    rig = json.loads((d / "signature.json").read_text())["camera"]
    target = target_from_dict(rec.rig["target"], "target")
    ids, local = target.points()

    joints = read_table(d / "stages" / "joints.arrow")
    det = read_table(d / "stages" / "detections.arrow")
    step = det.column("image").to_numpy()
    use = det.column("sweep").to_numpy() == POSES_SWEEP
    from pipeline.stages.frames import readings_at

    q = readings_at(joints, POSES_SWEEP, step[use], sig.robot.n_joints, sig.prismatic)
    T = forward_kinematics(sig.chain, joints_to_internal(q, sig.prismatic))  # the tool body
    c = local[np.searchsorted(ids, det.column("point_id").to_numpy()[use])]
    c_h = np.concatenate([c, np.ones((len(c), 1))], axis=1)
    if rig["setup"] == "eye-to-hand":  # the target on the flange, in the camera
        P = np.einsum("dij,dj->di", T, c_h)[:, :3]
    else:  # the camera on the flange, in the target's frame
        P = np.einsum("dij,dj->di", np.linalg.inv(T), c_h)[:, :3]
    k = np.array([r["value"] for r in rig["intrinsics"]])
    uv = np.stack([det.column("u_px").to_numpy()[use], det.column("v_px").to_numpy()[use]], 1)
    return uv, project(P, k)


@pytest.mark.parametrize(("robot", "setup"), [("puma560", "eye-to-hand"), (UR10, "eye-in-hand")])
def test_noiseless_signature_reprojects_the_pixels_and_passes(
    tmp_path: Path, robot: str, setup: str
) -> None:
    d = _identified(tmp_path, setup, robot, 40, noiseless=True)
    doc = json.loads((d / "signature.json").read_text())
    cam = doc["camera"]
    assert cam["setup"] == setup and [r["name"] for r in cam["intrinsics"]][:2] == ["fx", "fy"]
    assert all(r["sigma"] >= 0 for r in cam["intrinsics"]) and doc["model"] == "refined"
    fixed, moving = ("camera", "target") if setup == "eye-to-hand" else ("target", "camera")
    X = np.array(doc["design_alignment"]["sensor_from_design_base"])
    assert np.allclose(np.array(cam[f"{fixed}_in_base"]), invert_transform(X), atol=1e-12)
    assert f"{moving}_in_flange" in cam and doc["refinement"]["level"] == "pixels"
    uv, predicted = _reprojected(d)
    assert np.abs(predicted - uv).max() < 1e-6  # the file alone meets the pixels
    verdict = read_table(d / "stages" / "verdict.arrow").to_pylist()[0]
    assert verdict["verdict"] == PASS, verdict["line"]
    assert verdict["predicted_rms_cm"] < 1e-6 and verdict["holdout_rms_cm"] is None
    hold = read_table(d / "stages" / "camera_holdout.arrow")
    assert hold.num_rows == 8 and hold.column("rms_px").to_numpy().max() < 1e-6
    assert hold.column("design_rms_px").to_numpy().min() > 0.01  # the design chain's error
    assert doc["refinement"]["verdict"]["verdict"] == PASS


def test_noisy_session_predicts_its_held_out_images(tmp_path: Path) -> None:
    d = _identified(tmp_path, "eye-to-hand", poses=40, seed=3)
    hold = read_table(d / "stages" / "camera_holdout.arrow")
    rms = float(np.sqrt(np.mean(hold.column("rms_px").to_numpy() ** 2)))
    expected = float(np.sqrt(np.mean(hold.column("expected_px").to_numpy() ** 2)))
    assert hold.num_rows == 8 and 0.7 < rms / expected < 1.4  # 8 images × ~30 points
    assert 0.25 < expected < 0.35  # √2 × 0.2 px and the refit's part
    verdict = read_table(d / "stages" / "verdict.arrow").to_pylist()[0]
    assert verdict["verdict"] == PASS and verdict["gain"] > 2.0, verdict["line"]
    assert 0.8 < verdict["chi2_per_dof"] < 1.2 and verdict["unmodelled_rms_cm"] == 0.0
    unc = read_table(d / "stages" / "uncertainty.arrow")
    total = unc.column("sigma_total_cm").to_numpy()
    raw = unc.column("sigma_position_cm").to_numpy()
    assert np.allclose(total, raw) and (unc.column("sigma_position_aligned_cm").to_numpy()
                                        <= raw + 1e-12).all()  # fmt: skip
    assert 0.005 < float(np.sqrt(np.mean(raw**2))) < 0.2  # cm: the 40-image Puma's ~0.05


def test_urdf_places_the_camera_per_rep_103_and_camera_info_round_trips(tmp_path: Path) -> None:
    import xml.etree.ElementTree as ET

    from pipeline.export import export
    from pipeline.export.camera_info import export_camera_info, signature_intrinsics
    from pipeline.sensor.camera_info import intrinsics_from_camera_info

    for setup in ("eye-to-hand", "eye-in-hand"):
        d = _identified(tmp_path, setup, noiseless=True)
        r = export(d, "urdf")
        root = ET.parse(r.path).getroot()
        joints = {j.get("name"): j for j in root.iter("joint")}

        optical = _origin(joints, "camera_joint") @ _origin(joints, "camera_optical_joint")
        R = _origin(joints, "camera_optical_joint")[:3, :3]  # optical axes in camera_link
        assert np.allclose(R, [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)
        doc = json.loads((d / "signature.json").read_text())
        parent = joints["camera_joint"].find("parent")
        assert parent is not None
        if setup == "eye-to-hand":  # the camera in base_link: the design base
            assert parent.get("link") == "base_link"
            assert np.allclose(optical, doc["camera"]["camera_in_base"], atol=1e-9)
        else:  # on the last joint's link, where the URDF's tool (the camera) hangs
            assert parent.get("link") == "j6_link" or parent.get("link", "").endswith("_link")
            assert np.allclose(optical, _origin(joints, "tool_joint"), atol=1e-9)
        c = export_camera_info(d)
        back = intrinsics_from_camera_info(Path(c.path).read_text(), c.path).vector()
        assert np.array_equal(back, signature_intrinsics(doc["camera"]).vector())
    with pytest.raises(ArmsigError, match="camera session"):
        _point_session_camera_info(tmp_path)


def _origin(joints: dict, name: str) -> np.ndarray:
    """A URDF joint's ``<origin>`` (4, 4), cm."""
    o = joints[name].find("origin")
    assert o is not None
    xyz = [float(v) * 100 for v in o.get("xyz", "").split()]
    return transform_from_xyz_rpy(xyz, [float(v) for v in o.get("rpy", "").split()])


def _point_session_camera_info(tmp: Path) -> None:
    from pipeline.export.camera_info import export_camera_info
    from pipeline.identify import identify

    d = tmp / "pose"
    simulate_session(d, SimulationOptions(sensor="tracker", poses=40, sweeps=False,
                                          noiseless=True))  # fmt: skip
    identify(d, report=False)
    export_camera_info(d)


def test_load_fleet_row_and_report_of_a_camera_session(tmp_path: Path) -> None:
    import armsig
    from pipeline.fleet.row import session_row
    from pipeline.identify import identify

    d = _identified(tmp_path, "eye-in-hand", poses=40, noiseless=True)
    arm = armsig.load(d)
    T = arm.fk([10, -20, 30, 40, 50, 60])
    q = arm.ik(T, near=[12, -18, 28, 38, 52, 58])
    assert np.allclose(q, [10, -20, 30, 40, 50, 60], atol=1e-6)
    row = session_row(d, "identify")
    assert row["sensor"] == "camera" and row["verdict"] == PASS
    report = identify(d).report
    assert report is not None
    text = report.read_text(encoding="utf-8")
    assert "## Verdict: PASS" in text and "## Held-out images" in text
    assert "## Reprojection per image" in text and "## Predicted accuracy" in text
    assert (report.parent / "camera_residuals.png").is_file()
    from pipeline.planning import plan_from_session

    with pytest.raises(ArmsigError, match="not a camera's images"):  # plan --from: one line
        plan_from_session(d, 10)


def _evidence() -> Evidence:
    return Evidence(refined=True, status="converged", chi2_per_dof=1.0, predicted_rms_cm=0.05,
                    predicted_p95_cm=0.07, design_misfit_cm=0.3, reach_cm=176.6)  # fmt: skip


@pytest.mark.parametrize(
    ("rms", "expected", "design", "level", "rule"),
    [
        (0.28, 0.28, 2.0, PASS, None),
        (0.7, 0.28, 2.0, CHECK, "holdout_ratio"),  # 2.5 × its prediction
        (1.0, 0.28, 2.0, FAIL, "holdout_fail_ratio"),  # 3.6 ×
        (0.3, 0.28, 0.29, CHECK, "min_gain"),  # no better than the design chain
        (1e-9, 0.0, 1e-9, PASS, None),  # noiseless: below the pixel floor
    ],
)
def test_pixel_rules(
    rms: float, expected: float, design: float, level: str, rule: str | None
) -> None:
    wobble = 0.3 * np.resize([1.0, -1.0], 8)  # images differ; the design's the other way
    h = PixelHoldout(rms * (1 + wobble), np.full(8, expected), design * (1 - wobble))
    v = judge_camera(_evidence(), h, 0.2, Thresholds())
    assert v.level == level, v.line
    assert [r.rule for r in pixel_reasons(h, Thresholds())][:1] == ([rule] if rule else [])
    assert v.line.startswith(level) and " px" in v.line


def test_design_chain_significantly_better_fails() -> None:
    h = PixelHoldout(np.full(8, 0.6) + np.arange(8) * 1e-3, np.full(8, 0.5), np.full(8, 0.3))
    v = judge_camera(_evidence(), h, 0.2, Thresholds())
    assert v.level == FAIL and any("worse than the design chain" in r for r in v.reasons)


def test_reading_covariance_is_the_dense_sandwich(tmp_path: Path) -> None:
    """``H⁻¹ (Σ_i J_iᵀ G_i Σ_q G_iᵀ J_i) H⁻¹`` grouped by image equals the dense
    ``H⁻¹ Jᵀ C J H⁻¹`` with ``C`` the readings' block-diagonal pixel covariance; zero
    without reading noise; the stage's covariance holds it."""
    from pipeline.refine.camera_fit import fit_camera
    from pipeline.refine.camera_readings import reading_covariance, reading_jacobian
    from pipeline.refine.solve import Problem, residuals_and_jacobian
    from pipeline.stages import camera_fit, detections, joints, session
    from pipeline.stages.base import RECORDING, NoParams

    d = tmp_path / "s"
    simulate_session(d, SimulationOptions(sensor="camera", setup="eye-in-hand", poses=12))
    t: dict = {RECORDING: read_recording(d / "recording.mcap")}
    for stage in (session, joints, detections):
        t[stage.STAGE.name] = stage.STAGE.compute(t, NoParams())
    det, design, lens, setup = camera_fit.detections_for_fit(t)
    fit = fit_camera(det, design, lens, setup)
    x = fit.solution.x
    J = residuals_and_jacobian(Problem(fit.model, fit.block), x)[1]
    H_inv = fit.solution.covariance / fit.solution.noise_scale**2
    sigma_q = camera_fit.reading_sigma(t["session"])
    G = reading_jacobian(fit.block, fit.model, x)
    image = np.repeat(fit.block.image, 2)
    C = (G * sigma_q**2) @ G.T * (image[:, None] == image[None, :])
    dense = H_inv @ J[: len(G)].T @ C @ J[: len(G)] @ H_inv
    grouped = reading_covariance(fit.block, fit.model, x, J, H_inv, sigma_q)
    assert np.abs(grouped - dense).max() <= 1e-9 * np.abs(dense).max(), (
        np.abs(grouped - dense).max() / np.abs(dense).max()
    )
    assert np.abs(reading_covariance(fit.block, fit.model, x, J, H_inv, 0 * sigma_q)).max() == 0
    with_q = fit_camera(det, design, lens, setup, reading_sigma=sigma_q)
    n = fit.model.n_params
    assert np.trace(with_q.solution.covariance[:n, :n]) > np.trace(fit.solution.covariance[:n, :n])
