"""A camera session of flange poses without joints (issue 40, pipeline.refine.hand_eye):
both hand-eye transforms and the lens from pixels, the flange poses as given.

Noiseless sessions drawn here (OpenCV's ``projectPoints`` through a distorted lens, no
armsig projection) identify exactly; a recording written as the image-set importer
writes it runs through ``identify`` to the calibration file, ``camera_info.yaml``, the
report and the verdict line that says the arm is not calibrated."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.contract.channels import IMAGE_SET_CHANNELS
from pipeline.errors import ArmsigError, RecordingError, StageError
from pipeline.identify import identify
from pipeline.importers.images import ImageEntry, ImageSet, image_set_messages, import_image_set
from pipeline.kinematics.transforms import invert_transform
from pipeline.refine.hand_eye import fit_hand_eye, fixed_in_base, flange_detections, tool_in_flange
from pipeline.rig.camera_render import render
from pipeline.rig.recorder import write_recording
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.camera_info import intrinsics_from_camera_info
from pipeline.sensor.detect import ImageDetection
from pipeline.sensor.target import Target
from pipeline.stages.inspection import session_status
from pipeline.stages.recording import read_recording
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_table

TARGET = Target("charuco", 6, 8, 3.5, 2.6, "DICT_5X5_100")
TRUE = Intrinsics(1280, 960, 1010.0, 1005.0, 650.0, 470.0, -0.12, 0.05, 5e-4, -3e-4, 0.0)
STATED = Intrinsics(1280, 960, 1000.0, 1000.0, 640.0, 480.0)


def _pose(rvec: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rotation.from_rotvec(rvec).as_matrix(), t
    return T


def _session(setup: str, n: int = 16, seed: int = 1, lens: Intrinsics = TRUE) -> dict:
    """Random views of the target, 60-110 cm from the camera, tilted up to 35°; the flange
    poses that put them there; the detections (every point inside the image)."""
    rng = np.random.default_rng(seed)
    fixed = _pose(np.array([2.0, 0.3, -0.4]), np.array([20.0, 130.0, 60.0]))
    tool = _pose(np.array([0.2, -0.5, 1.1]), np.array([3.0, -2.0, 12.0]))
    ids, local = TARGET.points()
    centre = local.mean(axis=0)
    K, dist = lens.opencv()
    flange, image, loc, uv, views = [], [], [], [], []
    while len(flange) < n:
        tilt = Rotation.from_rotvec(np.r_[rng.uniform(-0.6, 0.6, 2), rng.uniform(-3, 3)])
        R = tilt.as_matrix()  # the board's Z away from the camera: its front seen
        t = np.r_[rng.uniform(-15, 15, 2), rng.uniform(60, 110)] - R @ centre
        cam_target = np.eye(4)  # the target in the camera
        cam_target[:3, :3], cam_target[:3, 3] = R, t
        px = cv2.projectPoints(local, cv2.Rodrigues(R)[0], t, K, dist)[0][:, 0]
        if (
            (px < 5).any()
            or (px[:, 0] > TRUE.width_px - 5).any()
            or (px[:, 1] > TRUE.height_px - 5).any()
        ):
            continue
        if setup == "eye-to-hand":  # fixed = camera in base, tool = target on flange
            F = fixed @ cam_target @ invert_transform(tool)
        else:  # fixed = target in base, tool = camera on flange
            F = fixed @ invert_transform(cam_target) @ invert_transform(tool)
        image.append(np.full(len(ids), len(flange)))
        flange.append(F)
        loc.append(local)
        uv.append(px)
        views.append(cam_target)
    return {
        "views": np.array(views),
        "flange": np.array(flange),
        "image": np.concatenate(image),
        "local": np.concatenate(loc),
        "uv": np.concatenate(uv),
        "fixed": fixed,
        "tool": tool,
        "ids": ids,
    }


def _angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.degrees(Rotation.from_matrix(A[:3, :3].T @ B[:3, :3]).magnitude()))


@pytest.mark.parametrize("setup", ["eye-to-hand", "eye-in-hand"])
@pytest.mark.parametrize("intrinsics", ["fitted", "fixed"])
def test_noiseless_identifies_exactly(setup: str, intrinsics: str) -> None:
    """Both hand-eye transforms to 1e-6 cm and 1e-6°, the lens to 1e-6 relative; "fixed"
    holds the true lens (a lens calibrated beforehand)."""
    s = _session(setup)
    det = flange_detections(
        s["image"], s["local"], s["uv"], np.full(len(s["uv"]), 0.2), len(s["flange"])
    )
    lens = STATED if intrinsics == "fitted" else TRUE
    fit = fit_hand_eye(det, s["flange"], lens, setup, intrinsics)
    assert fit.rms_px < 1e-6
    for got, true in ((fixed_in_base(fit), s["fixed"]), (tool_in_flange(fit), s["tool"])):
        assert np.abs(got[:3, 3] - true[:3, 3]).max() < 1e-6
        assert _angle_deg(got, true) < 1e-6
    rel = np.abs(fit.intrinsics - TRUE.vector()) / np.maximum(np.abs(TRUE.vector()), 1.0)
    assert rel.max() < 1e-6


def _recording(sdir: Path, setup: str, extra: list | None = None, n: int = 16) -> Path:
    """The recording the image-set importer writes for the drawn session (no images)."""
    s = _session(setup, n)
    entries = []
    for i, F in enumerate(s["flange"]):
        at = s["image"] == i
        found = ImageDetection(s["ids"], s["uv"][at], np.full(at.sum(), 8.0), markers=24)
        entries.append(
            ImageEntry(
                f"images/{i}.png",
                sdir / "images" / f"{i}.png",
                f"{i:064x}",
                F,
                found,
                (TRUE.width_px, TRUE.height_px),
            )
        )
    iset = ImageSet(sdir / "cal_data.yaml", setup, STATED, TARGET, tuple(entries))
    sdir.mkdir(parents=True)
    rec = sdir / "recording.mcap"
    messages = [m for m in image_set_messages(iset) if m.topic != "/camera/images"]  # no files
    write_recording(rec, messages + (extra or []), IMAGE_SET_CHANNELS, {})
    return rec


def test_identify_writes_the_camera_calibration(tmp_path: Path) -> None:
    """identify: the stages, camera_calibration.json (hand-eye with σ, every intrinsic
    with σ), camera_info.yaml, the report with every image's rms, the verdict line that
    says the arm is not calibrated; a rerun runs nothing; intrinsics=fixed holds the lens."""
    sdir = tmp_path / "s"
    _recording(sdir, "eye-to-hand")
    assert read_recording(sdir / "recording.mcap").kind == "camera-flange"
    shown = io.StringIO()
    result = identify(sdir, progress=shown)
    assert shown.getvalue().lstrip("\r").startswith("identify ")  # its bar, not "evaluate"
    names = [r.name for r in result.runs]
    assert names == [
        "session",
        "flange_poses",
        "detections",
        "camera_fit",
        "camera_residuals",
        "hand_eye_holdout",
    ]
    assert result.signature is None and "not the arm" in result.warnings[0]
    assert result.verdict is not None and "CAMERA ONLY" in result.verdict
    assert "the arm is not calibrated" in result.verdict and "px held out" in result.verdict
    doc = json.loads((sdir / "camera_calibration.json").read_text())
    assert doc["rms_px"] < 1e-6 and doc["arm"].startswith("not calibrated")
    held = doc["held_out"]  # noiseless: every image held out is predicted exactly
    assert held["folds"] == 5 and len(held["images"]) == 16 and held["rms_px"] < 1e-6
    assert doc["camera_in_base"]["translation_cm"] == pytest.approx([20.0, 130.0, 60.0], abs=1e-6)
    assert doc["target_in_flange"]["translation_cm"] == pytest.approx([3.0, -2.0, 12.0], abs=1e-6)
    assert set(doc["sigma_intrinsics"]) == {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"}
    assert len(doc["images"]) == 16
    info = intrinsics_from_camera_info((sdir / "camera_info.yaml").read_text())
    assert info.vector() == pytest.approx(TRUE.vector(), rel=1e-6, abs=1e-6)
    report = (sdir / "report" / "report.md").read_text()
    assert "the arm is not calibrated" in report.lower() and "| 15 | 35 |" in report
    assert "## Held-out images" in report and "px held out**" in report
    again = identify(sdir)
    assert {r.action for r in again.runs} == {"cached"}
    with pytest.raises(StageError) as err:  # what needs an arm (audit, ...) says so
        session_robot(read_table(sdir / "stages" / "session.arrow"))
    assert "has no arm" in str(err.value) and "\n" not in str(err.value)
    assert {s.state for s in session_status(sdir)} == {"fresh"}
    held = identify(sdir, overrides={"camera_fit": {"intrinsics": "fixed"}})
    assert "lens as given" in (held.verdict or "")
    fixed = json.loads((sdir / "camera_calibration.json").read_text())
    assert fixed["intrinsics"]["fx"] == STATED.fx and fixed["rms_px"] > 0.5


def test_detections_without_a_flange_pose_refused(tmp_path: Path) -> None:
    """An image's detections without its flange pose: one line naming the image."""
    from pipeline.rig.recorder import Message

    extra = [Message("/camera/detections", 10**18, {
        "sweep": "poses", "step": 99, "point_ids": [0, 1, 2], "u_px": [1.0, 2.0, 3.0],
        "v_px": [1.0, 2.0, 3.0], "sigma_px": 0.2})]  # fmt: skip
    _recording(tmp_path / "s", "eye-in-hand", extra)
    with pytest.raises(RecordingError) as err:
        read_recording(tmp_path / "s" / "recording.mcap")
    assert "step 99) has no /robot/flange_pose" in str(err.value)
    assert "\n" not in str(err.value)


def _rendered_set(folder: Path, setup: str) -> tuple[Path, dict]:
    """The drawn session rendered (no distortion: the renderer's), in industrial_calibration's
    layout: images, pose files (m, quaternion), cal_data.yaml."""
    lens = Intrinsics(800, 600, 700.0, 700.0, 400.0, 300.0)
    s = _session(setup, n=12, lens=lens)
    (folder / "images").mkdir(parents=True)
    (folder / "poses").mkdir()
    lines = ["data:"]
    for k, (F, view) in enumerate(zip(s["flange"], s["views"], strict=True)):
        cv2.imwrite(str(folder / "images" / f"{k}.png"), render(TARGET, view, lens, px_per_cm=20))
        q = [float(v) for v in Rotation.from_matrix(F[:3, :3]).as_quat()]
        x, y, z = (float(v) / 100 for v in F[:3, 3])
        (folder / "poses" / f"{k}.yaml").write_text(
            f"x: {x!r}\ny: {y!r}\nz: {z!r}\nqx: {q[0]!r}\nqy: {q[1]!r}\nqz: {q[2]!r}\n"
            f"qw: {q[3]!r}\n")  # fmt: skip
        lines += [f"  - image: images/{k}.png", f"    pose: poses/{k}.yaml"]
    lines += [
        "target_finder:", "  type: CharucoGridTargetFinder", "  rows: 6", "  cols: 8",
        "  chessboard_dim: 0.035", "  aruco_marker_dim: 0.026", "  dictionary: 6",
        "intrinsics:", "  fx: 700.0", "  fy: 700.0", "  cx: 400.0", "  cy: 300.0",
        f"static_camera: {'true' if setup == 'eye-to-hand' else 'false'}",
    ]  # fmt: skip
    (folder / "cal_data.yaml").write_text("\n".join(lines) + "\n")
    return folder / "cal_data.yaml", s


def test_detections_stage_detects_the_referenced_images(tmp_path: Path) -> None:
    """Rendered images imported as they are: the detections stage detects them (one row
    per corner found), a rerun detects nothing, a changed image makes the session stale
    (status names it) and identify refuses it in one line; restored, all is fresh."""
    cal, s = _rendered_set(tmp_path / "set", "eye-in-hand")
    sdir = tmp_path / "s"
    import_image_set(cal, sdir)
    result = identify(sdir, overrides={"camera_fit": {"intrinsics": "fixed"}})
    ran = {r.name: r for r in result.runs}
    recorded = len(read_recording(sdir / "recording.mcap").detection_point)  # at import
    assert ran["detections"].action == "ran" and ran["detections"].rows == recorded > 12 * 30
    doc = json.loads((sdir / "camera_calibration.json").read_text())
    assert doc["rms_px"] < 0.2  # rendered corners: 0.06-0.2 px from the truth (detect.py)
    fixed, tool = doc["target_in_base"], doc["camera_in_flange"]
    assert np.abs(np.array(fixed["translation_cm"]) - s["fixed"][:3, 3]).max() < 0.05
    assert np.abs(np.array(tool["translation_cm"]) - s["tool"][:3, 3]).max() < 0.05
    again = identify(sdir, overrides={"camera_fit": {"intrinsics": "fixed"}})
    assert {r.action for r in again.runs} == {"cached"}
    image = tmp_path / "set" / "images" / "3.png"
    kept = image.read_bytes()
    shutil.copy(tmp_path / "set" / "images" / "4.png", image)
    states = {st.name: st for st in session_status(sdir)}
    assert states["detections"].state == "stale"
    assert "image images/3.png is not the one the recording holds" in states["detections"].reason
    with pytest.raises(ArmsigError) as err:
        identify(sdir, overrides={"camera_fit": {"intrinsics": "fixed"}})
    assert "images/3.png" in str(err.value) and "\n" not in str(err.value)
    image.write_bytes(kept)
    states = {st.name: st for st in session_status(sdir)}  # the default lens: fitted
    assert (states["detections"].state, states["camera_fit"].reason) == (
        "fresh",
        "parameters changed",
    )
