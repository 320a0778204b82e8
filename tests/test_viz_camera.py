"""`pipeline viz` of a camera session (issue 40): each rendered image as a
foxglove.CompressedImage with its detected and reprojected corners as
foxglove.ImageAnnotations, the frustum and the target in the 3-D scene, the body on the
flange where the fit puts it; every message valid against its published schema."""

from __future__ import annotations

import base64
import hashlib
import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.schemas import schema_dir
from pipeline.stages.inspection import stage_table
from pipeline.stages.recording import read_recording
from pipeline.viz.foxglove import SCHEMAS
from pipeline.viz.write import viz
from tests.test_viz import read_viz, strict

UR10 = str(Path(__file__).resolve().parents[1] / "examples" / "ur10_ipa" / "ur10.toml")


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("vizcam") / "cam"
    opts = SimulationOptions(robot=UR10, sensor="camera", setup="eye-in-hand", poses=12,
                             images=True, resolution_px=(640, 480), seed=3)  # fmt: skip
    simulate_session(d, opts)
    identify(d, report=False)
    return d


def test_every_message_valid_and_each_image_annotated(session: Path) -> None:
    r = viz(session)
    messages = read_viz(r.path)
    by_topic: dict[str, list] = {}
    for schema, channel, msg in messages:
        committed = (schema_dir() / "foxglove" / SCHEMAS[schema.name]).read_bytes()
        assert schema.data == committed and channel.message_encoding == "json"
        jsonschema.Draft202012Validator(strict(json.loads(schema.data))).validate(msg)
        by_topic.setdefault(channel.topic, []).append(msg)
    rec = read_recording(session / "recording.mcap")
    n = len(rec.joint_step)
    assert len(by_topic["/camera/image"]) == len(by_topic["/camera/annotations"]) == n
    assert len(by_topic["/tf"]) == n + 1 and len(by_topic["/camera/scene"]) == 1
    # the images are the referenced PNGs, byte for byte
    kept = {int(s): h for s, h, d in zip(rec.image_step, rec.image_sha256, rec.image_dropped,
                                         strict=True) if not d}  # fmt: skip
    for k, msg in enumerate(by_topic["/camera/image"]):
        png = base64.b64decode(msg["data"])
        assert msg["format"] == "png" and msg["frame_id"] == "camera"
        assert hashlib.sha256(png).hexdigest() == kept[int(rec.joint_step[k])]
    # detected corners: the stage's pixels + 0.5 (Foxglove's origin is a pixel's corner);
    # reprojected: detected plus the residual
    res = stage_table(session, "camera_residuals").table.to_pydict()
    first = np.asarray(res["image"]) == rec.joint_step[0]
    seen, again, vectors = by_topic["/camera/annotations"][0]["points"]
    got = np.array([[p["x"], p["y"]] for p in seen["points"]])
    want = np.stack([res["u_px"], res["v_px"]], 1)[first] + 0.5
    assert np.abs(got - want).max() < 1e-12
    got = np.array([[p["x"], p["y"]] for p in again["points"]])
    want = want + np.stack([res["du_px"], res["dv_px"]], 1)[first]
    assert np.abs(got - want).max() < 1e-12
    assert len(vectors["points"]) == 2 * len(seen["points"])
    # eye-in-hand: the target at the sensor frame's origin, the camera where the fit puts
    # it; its frustum reaches the farthest of them
    tf = [m for m in by_topic["/tf"] if m["child_frame_id"] == "camera"]
    far = max(np.linalg.norm(list(m["translation"].values())) for m in tf)
    assert len(tf) == n and far > 0.3
    frustum = by_topic["/camera/scene"][0]["entities"][0]
    corner = frustum["lines"][0]["points"][1]
    assert frustum["frame_id"] == "camera" and corner["z"] == pytest.approx(far)
    assert r.configuration == [] and r.topics["/camera/image"] == n


def test_camera_viz_refuses_q_and_a_stale_session(session: Path) -> None:
    with pytest.raises(ArmsigError, match="--q does not apply"):
        viz(session, q=[0.0] * 6)
    rec = read_recording(session / "recording.mcap")
    png = session / "images" / str(rec.image_file[0])
    png.write_bytes(png.read_bytes() + b"\0")
    with pytest.raises(ArmsigError, match="stage detections is stale"):
        viz(session, out=session / "other.mcap")
