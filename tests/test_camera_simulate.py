"""The simulated camera rig (pipeline.rig.camera, camera_session): its recordings against
OpenCV's projection of the truth, its detector's drops, the reader's and options' checks."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from pipeline.errors import ArmsigError, RecordingError
from pipeline.kinematics.chain import SerialChain, link_frames
from pipeline.kinematics.transforms import invert_transform, rot_x, trans
from pipeline.rig import camera
from pipeline.rig.recorder import Message, write_recording
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots import get_robot
from pipeline.sensor.camera import Intrinsics
from pipeline.sensor.target import Target
from pipeline.stages import detections
from pipeline.stages.base import RECORDING, NoParams
from pipeline.stages.recording import read_recording
from pipeline.units import joints_to_internal

UR10 = str(Path(__file__).resolve().parents[1] / "examples" / "ur10_ipa" / "ur10.toml")


def _session(tmp: Path, setup: str, robot: str = "puma560", **kw) -> Path:
    opts = SimulationOptions(robot=robot, sensor="camera", setup=setup, poses=12, **kw)
    simulate_session(tmp / setup, opts)
    return tmp / setup


@pytest.mark.parametrize("robot", ["puma560", UR10])
@pytest.mark.parametrize("setup", camera.SETUPS)
def test_noiseless_detections_are_opencvs_projection_of_the_truth(
    tmp_path: Path, setup: str, robot: str
) -> None:
    d = _session(tmp_path, setup, robot, noiseless=True)
    truth = json.loads((d / "rig-truth.json").read_text())
    tk, cam = truth["true_kinematics"], truth["camera"]
    rec = read_recording(d / "recording.mcap")
    table = detections.compute({RECORDING: rec}, NoParams())
    assert table.num_rows == len(rec.detection_point) > 12 * camera.MIN_POINTS
    desc = get_robot(robot)
    # the truth's chain: its base is the world, sensor_from_base the fixed part's inverse
    true_chain = SerialChain(np.array(tk["links"]), desc.prismatic,
                             invert_transform(np.array(truth["sensor_from_base"]))
                             @ np.array(tk["base"]))  # fmt: skip
    F = link_frames(true_chain, joints_to_internal(rec.q_encoder, desc.prismatic))[:, -2]
    lens = Intrinsics.from_dict(cam["intrinsics_true"])
    ids, local = camera.DEFAULT_TARGET.points()
    worst = 0.0
    for k in range(len(F)):
        if setup == "eye-to-hand":
            T = (
                invert_transform(np.array(cam["camera_in_world"]))
                @ F[k]
                @ np.array(cam["target_in_flange"])
            )
        else:
            T = invert_transform(F[k] @ np.array(cam["camera_in_flange"])) @ np.array(
                cam["target_in_world"]
            )
        rvec, _ = cv2.Rodrigues(T[:3, :3])
        ref, _ = cv2.projectPoints(local, rvec, T[:3, 3], *lens.opencv())
        sel = rec.detection_step == k
        uv = rec.detection_uv_px[sel]
        worst = max(worst, float(np.abs(uv - ref[rec.detection_point[sel], 0]).max()))
    assert worst < 1e-8  # px: the truth chain's products in another order than the rig's


def test_noisy_pixels_scatter_by_sigma(tmp_path: Path) -> None:
    noisy = read_recording(_session(tmp_path / "a", "eye-to-hand") / "recording.mcap")
    exact = read_recording(_session(tmp_path / "b", "eye-to-hand", noiseless=True)
                           / "recording.mcap")  # fmt: skip
    assert np.array_equal(noisy.detection_point, exact.detection_point)
    err = noisy.detection_uv_px - exact.detection_uv_px  # the servo moves them too (~0.01 px)
    assert 0.17 < err.std() < 0.23 and (noisy.detection_sigma_px == 0.2).all()


def _pose(z_cm: float, tilt_deg: float = 0.0, shift_cm: float = 0.0) -> np.ndarray:
    centre = camera.target_centre(Target("checkerboard", 6, 8, 3.5))
    T = trans(shift_cm, 0.0, z_cm) @ rot_x(np.radians(tilt_deg)) @ trans(*(-centre))
    return np.asarray(T, float)[None]


@pytest.mark.parametrize(
    "pose, reason",
    [
        (_pose(100.0), -1),
        (_pose(100.0, 180.0), camera.DROP_REASONS.index("back_face")),
        (_pose(100.0, 70.0), camera.DROP_REASONS.index("oblique")),
        (_pose(100.0, 50.0), -1),
        (_pose(500.0), camera.DROP_REASONS.index("far")),
        (_pose(100.0, 0.0, 65.0), camera.DROP_REASONS.index("out_of_view")),
        (_pose(-100.0), camera.DROP_REASONS.index("behind")),
    ],
)
def test_detector_drops_as_a_detector_would(pose: np.ndarray, reason: int) -> None:
    lens = camera.nominal_intrinsics(1280, 960, 1000.0)
    board = Target("checkerboard", 6, 8, 3.5)
    kept, _, why = camera.detect(board, pose, lens, board.points()[1])
    assert why[0] == reason and kept[0] == (reason < 0)


def test_a_charuco_board_partly_in_view_keeps_its_visible_corners() -> None:
    lens = camera.nominal_intrinsics(1280, 960, 1000.0)
    board = camera.DEFAULT_TARGET
    pose = _pose(100.0, 0.0, 65.0)  # the checkerboard of the same size is dropped here
    kept, found, _ = camera.detect(board, pose, lens, board.points()[1])
    assert kept[0] and camera.MIN_POINTS <= found.sum() < found.size


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"poses": 0}, "--poses from 4"),
        ({"poses": 10, "check": 3}, "--check does not apply"),
        ({"poses": 10, "setup": "on-the-wall"}, "unknown camera set-up"),
        ({"poses": 10, "focal_px": -5.0}, "camera options out of range"),
    ],
)
def test_bad_camera_options_are_one_line(tmp_path: Path, kw: dict, words: str) -> None:
    with pytest.raises(ArmsigError) as err:
        simulate_session(tmp_path / "s", SimulationOptions(sensor="camera", **kw))
    assert words in str(err.value) and "\n" not in str(err.value)


def _rewrite(d: Path, change) -> Path:
    """The session's recording with its messages changed by ``change`` (in place)."""
    from pipeline.contract.channels import CAMERA_CHANNELS
    from pipeline.contract.mcap_read import read_mcap

    msgs = read_mcap(d / "recording.mcap", CAMERA_CHANNELS, "").messages
    out = []
    for topic, items in msgs.items():
        for t, m in items:
            out.append(Message(topic, t, change(topic, m)))
    out.sort(key=lambda m: m.time_ns)
    path = d / "changed.mcap"
    write_recording(path, out, CAMERA_CHANNELS)
    return path


def _short(topic: str, m: dict) -> dict:
    if topic == "/camera/detections" and m["step"] == 3:
        m = {**m, "u_px": m["u_px"][:-1]}
    return m


def _foreign_id(topic: str, m: dict) -> dict:
    if topic == "/camera/detections" and m["step"] == 2:
        m = {**m, "point_ids": [*m["point_ids"][:-1], 9999]}
    return m


@pytest.mark.parametrize(
    "change, words", [(_short, "differ in length"), (_foreign_id, "point id 9999")]
)
def test_bad_detections_are_one_line(tmp_path: Path, change, words: str) -> None:
    path = _rewrite(_session(tmp_path, "eye-to-hand", noiseless=True), change)
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_identify_writes_the_detections_table_the_signature_and_the_report(
    tmp_path: Path,
) -> None:
    import polars as pl

    from pipeline.identify import identify

    d = _session(tmp_path, "eye-in-hand", noiseless=True)
    result = identify(d)
    assert result.signature == d / "signature.json" and result.verdict is not None
    assert result.report is not None
    report = result.report.read_text(encoding="utf-8")
    per_image = report.split("## Reprojection per image")[1]
    assert per_image.count("\n| ") == 12 + 1  # a header and one row per image
    assert "camera.fx" in report and "tool_rot.rz" in report
    assert (result.report.parent / "camera_residuals.png").stat().st_size > 1000
    residuals = pl.read_ipc(d / "stages" / "camera_residuals.arrow")
    rms = float(np.sqrt((residuals["du_px"] ** 2 + residuals["dv_px"] ** 2).mean()))
    fit = pl.read_ipc(d / "stages" / "camera_fit.arrow")
    assert residuals.height == len(read_recording(d / "recording.mcap").detection_point)
    assert rms < 1e-6 and fit.height == 39  # noiseless: the pixels are met exactly
    table = pl.read_ipc(d / "stages" / "detections.arrow")
    rec = read_recording(d / "recording.mcap")
    assert table.height == len(rec.detection_point) and table["image"].n_unique() == 12
    assert table.schema["u_px"] == pl.Float64


def test_commands_that_need_a_signature_work_on_a_camera_session(tmp_path: Path) -> None:
    """fk and export of an identified camera session (they refused it before its signature
    was written, issue 39)."""
    from typer.testing import CliRunner

    from pipeline.cli import app
    from pipeline.identify import identify

    d = _session(tmp_path, "eye-to-hand", noiseless=True)
    identify(d, report=False)
    for args in (["fk", str(d), "--q", "0,0,0,0,0,0"], ["export", str(d), "--format", "urdf"],
                 ["export", str(d), "--format", "camera-info"]):  # fmt: skip
        out = CliRunner().invoke(app, args)
        assert out.exit_code == 0, out.output
