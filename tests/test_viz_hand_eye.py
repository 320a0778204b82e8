"""`pipeline viz` of a camera session of flange poses without joints (issue 40): the joint
camera session's images, annotations, frustum and target (pipeline/viz/camera.py) placed
by the recorded flange poses and the fitted hand-eye transforms (pipeline/viz/hand_eye.py).

A rendered set imported as industrial_calibration's (tests/test_hand_eye.py) and, skipped
when absent, the real ChArUco set: every message valid against its published schema made
strict, each image the referenced PNG byte for byte, the annotations the
``camera_residuals`` table's pixels, the flange at each recorded pose, and the frames
composed from the file alone reprojecting the target onto the annotated reprojections."""

from __future__ import annotations

import base64
import hashlib
import json
from pathlib import Path
from typing import Any

import cv2
import jsonschema
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bench.hand_eye_real import REALDATA
from pipeline.identify import identify
from pipeline.importers.images import import_image_set
from pipeline.schemas import schema_dir
from pipeline.sensor.camera import Intrinsics
from pipeline.stages.flange_poses import flange_matrices
from pipeline.stages.inspection import stage_table
from pipeline.stages.recording import read_recording
from pipeline.viz.foxglove import SCHEMAS
from pipeline.viz.write import viz
from tests.test_hand_eye import _rendered_set
from tests.test_viz import read_viz, strict


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("vizflange")
    cal, _ = _rendered_set(root / "set", "eye-to-hand")
    import_image_set(cal, root / "s")
    identify(root / "s", report=False)
    return root / "s"


def _matrix(tf: dict[str, Any]) -> np.ndarray:
    """A foxglove.FrameTransform as a 4 × 4 matrix in cm."""
    T = np.eye(4)
    r, t = tf["rotation"], tf["translation"]
    T[:3, :3] = Rotation.from_quat([r["x"], r["y"], r["z"], r["w"]]).as_matrix()
    T[:3, 3] = np.array([t["x"], t["y"], t["z"]]) * 100.0
    return T


def _by_topic(path: Path) -> dict[str, list[dict[str, Any]]]:
    """Every message, validated against its channel's schema made strict, by topic."""
    out: dict[str, list[dict[str, Any]]] = {}
    for schema, channel, msg in read_viz(path):
        committed = (schema_dir() / "foxglove" / SCHEMAS[schema.name]).read_bytes()
        assert schema.data == committed and channel.message_encoding == "json"
        jsonschema.Draft202012Validator(strict(json.loads(schema.data))).validate(msg)
        out.setdefault(channel.topic, []).append(msg)
    return out


def _check(sdir: Path) -> dict[str, list[dict[str, Any]]]:
    """The checks of the module docstring; the messages by topic."""
    r = viz(sdir)
    by_topic = _by_topic(r.path)
    rec = read_recording(sdir / "recording.mcap")
    res = stage_table(sdir, "camera_residuals").table.to_pydict()
    images = np.unique(res["image"])
    n = len(images)
    assert len(by_topic["/camera/image"]) == len(by_topic["/camera/annotations"]) == n
    assert r.topics["/tf"] == n + 2 and len(by_topic["/camera/scene"]) == 1
    assert r.configuration == []
    recorded = dict(zip(rec.image_step.tolist(), rec.image_sha256, strict=True))
    for k, msg in enumerate(by_topic["/camera/image"]):
        png = base64.b64decode(msg["data"])
        assert hashlib.sha256(png).hexdigest() == recorded[int(images[k])]
    doc = json.loads((sdir / "camera_calibration.json").read_text())
    setup = doc["setup"]
    fixed_name, moving = ("camera", "target") if setup == "eye-to-hand" else ("target", "camera")
    tf = by_topic["/tf"]
    fixed = _matrix(next(m for m in tf if m["child_frame_id"] == fixed_name))
    tool = _matrix(next(m for m in tf if m["child_frame_id"] == moving))
    flange = np.array([_matrix(m) for m in tf if m["child_frame_id"] == "flange"])
    fixed_key, tool_key = [k for k in doc if k.endswith("_in_base") or k.endswith("_in_flange")]
    assert np.abs(fixed - np.array(doc[fixed_key]["matrix_cm"])).max() < 1e-9
    assert np.abs(tool - np.array(doc[tool_key]["matrix_cm"])).max() < 1e-9
    recorded_flange = flange_matrices(stage_table(sdir, "flange_poses").table, images)
    assert np.abs(flange - recorded_flange).max() < 1e-9  # the recorded pose of every image
    # the frames of the file alone put the target where the annotations reproject it
    target_in_camera = np.linalg.inv(fixed) @ flange @ tool
    if setup == "eye-in-hand":
        target_in_camera = np.linalg.inv(target_in_camera)
    lens = Intrinsics(*doc["image_size_px"], **doc["intrinsics"])
    K, dist = lens.opencv()
    ids, local = _recorded_target(sdir)
    at_id = dict(zip(ids.tolist(), local, strict=True))
    uv = np.stack([res["u_px"], res["v_px"]], 1) + np.stack([res["du_px"], res["dv_px"]], 1)
    for k, ann in enumerate(by_topic["/camera/annotations"]):
        on = np.asarray(res["image"]) == images[k]
        pts = np.array([at_id[int(i)] for i in np.asarray(res["point_id"])[on]])
        T = target_in_camera[k]
        px = cv2.projectPoints(pts, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K, dist)[0][:, 0]
        got = np.array([[p["x"], p["y"]] for p in ann["points"][1]["points"]]) - 0.5
        assert np.abs(got - uv[on]).max() < 1e-9  # the table's reprojections
        assert np.abs(px - uv[on]).max() < 1e-5  # the file's frames and lens reproduce them
    frustum, target, poses = by_topic["/camera/scene"][0]["entities"]
    assert (frustum["frame_id"], target["frame_id"], poses["frame_id"]) == (
        "camera", "target", "base")  # fmt: skip
    far = np.linalg.norm(target_in_camera[:, :3, 3], axis=1).max() / 100.0
    assert frustum["lines"][0]["points"][1]["z"] == pytest.approx(far)
    assert len(poses["spheres"]) == n
    return by_topic


def _recorded_target(sdir: Path) -> tuple[np.ndarray, np.ndarray]:
    from pipeline.sensor.target import target_from_dict

    rig = json.loads(stage_table(sdir, "session").table.column("rig_json")[0].as_py())
    return target_from_dict(rig["target"], "target").points()


def test_flange_session_viz(session: Path) -> None:
    by_topic = _check(session)
    assert len(by_topic["/camera/image"]) == 12


def test_flange_session_viz_refuses_a_stale_session(session: Path) -> None:
    from pipeline.errors import ArmsigError

    rec = read_recording(session / "recording.mcap")
    png = Path(rec.path).parent / rec.rig["images_dir"] / str(rec.image_file[0])
    kept = png.read_bytes()
    png.write_bytes(kept + b"\0")
    try:
        with pytest.raises(ArmsigError, match="stage detections is stale"):
            viz(session, out=session / "other.mcap")
    finally:
        png.write_bytes(kept)


def test_viz_of_a_session_identified_with_a_param(tmp_path: Path) -> None:
    """`identify --param camera_fit.intrinsics=fixed`, then `viz`: the session is fresh at
    the parameters it was identified with (the freshness check compared them with the
    defaults and refused it); a changed input is still refused."""
    from pipeline.errors import ArmsigError

    cal, _ = _rendered_set(tmp_path / "set", "eye-to-hand")
    sdir = tmp_path / "s"
    import_image_set(cal, sdir)
    identify(sdir, report=False, overrides={"camera_fit": {"intrinsics": "fixed"}})
    assert len(_check(sdir)["/camera/image"]) == 12
    rec = read_recording(sdir / "recording.mcap")
    png = Path(rec.path).parent / rec.rig["images_dir"] / str(rec.image_file[0])
    png.write_bytes(png.read_bytes() + b"\0")
    with pytest.raises(ArmsigError, match="stage detections is stale"):
        viz(sdir, out=sdir / "other.mcap")


CHARUCO = REALDATA / "industrial_calibration" / "test_set_charuco" / "cal_data.yaml"


@pytest.mark.skipif(not CHARUCO.is_file(), reason=f"no real ChArUco set at {CHARUCO}")
def test_real_charuco_viz(tmp_path: Path) -> None:
    """The real set imported as it is: 16 images, each with its corners and reprojections."""
    sdir = tmp_path / "charuco"
    import_image_set(CHARUCO, sdir)
    identify(sdir, report=False)  # the lens fitted
    by_topic = _check(sdir)
    assert len(by_topic["/camera/image"]) == 16
