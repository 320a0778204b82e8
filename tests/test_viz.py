"""`pipeline viz`: viz.mcap read back with the Python MCAP reader, every message valid
against its channel's Foxglove schema, and its numbers equal to the session's."""

from __future__ import annotations

import base64
import copy
import json
import shutil
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from recording_data import locked_elsewhere, small_session
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.identify import identify
from pipeline.kinematics.chain import link_frames
from pipeline.schemas import schema_dir
from pipeline.signature.session import load_session_signature
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table
from pipeline.units import joints_to_internal
from pipeline.viz.foxglove import SCHEMAS
from pipeline.viz.write import viz

runner = CliRunner()


@pytest.fixture(scope="module")
def session(identified_session: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("viz") / "s"
    shutil.copytree(identified_session, d)
    return d


@pytest.fixture(scope="module")
def viz_file(session: Path) -> Path:
    return viz(session).path


def read_viz(path: Path) -> list[tuple[Any, Any, dict[str, Any]]]:
    """(schema, channel, decoded JSON) of every message, CRCs checked."""
    with path.open("rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        return [(s, c, json.loads(m.data)) for s, c, m in reader.iter_messages()]


def strict(schema: Any) -> Any:
    """``schema`` with ``additionalProperties: false`` on every object that lists its
    properties: a field the published schema does not define is an error."""
    out = copy.deepcopy(schema)

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            if "properties" in node:
                node["additionalProperties"] = False
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(out)
    return out


def test_every_message_valid_against_its_channels_foxglove_schema(viz_file: Path) -> None:
    messages = read_viz(viz_file)
    assert len(messages) > 0
    for schema, channel, msg in messages:
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
        committed = (schema_dir() / "foxglove" / SCHEMAS[schema.name]).read_bytes()
        assert schema.data == committed  # the published text, as committed
        doc = json.loads(schema.data)
        assert doc["title"] == schema.name
        jsonschema.Draft202012Validator(strict(doc)).validate(msg)


def test_strict_check_catches_an_invented_field() -> None:
    doc = json.loads((schema_dir() / "foxglove" / "FrameTransform.json").read_bytes())
    msg = {
        "timestamp": {"sec": 0, "nsec": 0},
        "parent_frame_id": "a",
        "child_frame_id": "b",
        "translation": {"x": 0, "y": 0, "z": 0},
        "rotation": {"x": 0, "y": 0, "z": 0, "w": 1},
    }
    jsonschema.Draft202012Validator(strict(doc)).validate(msg)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.Draft202012Validator(strict(doc)).validate({**msg, "frame": "x"})


def test_topics_and_metadata(viz_file: Path, session: Path) -> None:
    topics = {(c.topic, s.name) for s, c, _ in read_viz(viz_file)}
    n = load_session_signature(session / "signature.json").robot.n_joints
    expected = {("/tf", "foxglove.FrameTransform"), ("/features", "foxglove.SceneUpdate")}
    expected |= {(f"/measured/joint_{i}", "foxglove.PointCloud") for i in range(1, n + 1)}
    assert expected <= topics
    with viz_file.open("rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().library.startswith("armsig-viz")
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert meta["armsig.viz"]["length_unit"] == "m"


def _points_m(msg: dict[str, Any]) -> np.ndarray:
    assert msg["point_stride"] == 24 and [f["name"] for f in msg["fields"]] == ["x", "y", "z"]
    return np.frombuffer(base64.b64decode(msg["data"]), "<f8").reshape(-1, 3)


def test_points_are_the_triangulated_positions_in_metres(viz_file: Path, session: Path) -> None:
    clouds = {c.topic: _points_m(m) for _, c, m in read_viz(viz_file) if c.topic.startswith("/m")}
    tri = read_table(stage_path(session, "triangulate")).to_pylist()
    for sweep in {r["sweep"] for r in tri}:
        rows = sorted((r for r in tri if r["sweep"] == sweep and r["x_cm"] is not None),
                      key=lambda r: r["step"])  # fmt: skip
        cm = np.array([[r["x_cm"], r["y_cm"], r["z_cm"]] for r in rows])
        topic = "/measured/tool" if sweep == 0 else f"/measured/joint_{sweep}"
        np.testing.assert_allclose(clouds[topic] * 100.0, cm, rtol=0, atol=1e-12)


def _in_sensor(tf: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """Every frame's pose (4, 4, metres) in ``sensor``, composed along the /tf tree."""
    parent = {m["child_frame_id"]: m for m in tf}
    out: dict[str, np.ndarray] = {"sensor": np.eye(4)}

    def pose(name: str) -> np.ndarray:
        if name not in out:
            m = parent[name]
            T = np.eye(4)
            r, t = m["rotation"], m["translation"]
            T[:3, :3] = Rotation.from_quat([r["x"], r["y"], r["z"], r["w"]]).as_matrix()
            T[:3, 3] = [t["x"], t["y"], t["z"]]
            out[name] = pose(m["parent_frame_id"]) @ T
        return out[name]

    for name in parent:
        pose(name)
    return out


@pytest.mark.parametrize("q", [None, [10.0, -20.0, 30.0, -40.0, 50.0, -60.0]])
def test_frames_are_the_signature_and_design_at_q(
    session: Path, tmp_path: Path, q: list[float] | None
) -> None:
    out = viz(session, q=q, out=tmp_path / "v.mcap")
    tf = [m for _, c, m in read_viz(out.path) if c.topic == "/tf"]
    frames = _in_sensor(tf)
    sig = load_session_signature(session / "signature.json")
    names = ["base", *(j.name for j in sig.robot.joints), "tool"]
    qi = joints_to_internal(out.configuration, sig.prismatic)
    if q is not None:
        np.testing.assert_allclose(out.configuration, q)
    F_s = link_frames(sig.chain, qi)
    F_d = sig.sensor_from_design_base @ link_frames(sig.robot.design_chain(), qi)
    for prefix, F in (("signature", F_s), ("design", F_d)):
        for name, T in zip(names, F, strict=True):
            got = frames[f"{prefix}/{name}"]
            np.testing.assert_allclose(got[:3, :3], T[:3, :3], atol=1e-12)
            np.testing.assert_allclose(got[:3, 3] * 100.0, T[:3, 3], atol=1e-9)  # cm
    probe = frames["design/probe"]
    T = F_d[-1] @ sig.design_flange_to_tool
    np.testing.assert_allclose(probe[:3, 3] * 100.0, T[:3, 3], atol=1e-9)


def test_features_circles_lie_at_the_fitted_radius(viz_file: Path, session: Path) -> None:
    (scene,) = [m for _, c, m in read_viz(viz_file) if c.topic == "/features"]
    feats = {f["joint"]: f for f in read_table(stage_path(session, "features")).to_pylist()}
    assert len(scene["entities"]) == len(feats)
    for e in scene["entities"]:
        f = feats[int(e["id"].removeprefix("joint_"))]
        pts = np.array([[p["x"], p["y"], p["z"]] for p in e["lines"][0]["points"]]) * 100.0
        centre = np.array([f["center_x_cm"], f["center_y_cm"], f["center_z_cm"]])
        axis = np.array([f["axis_x"], f["axis_y"], f["axis_z"]])
        if f["type"] == "revolute":
            np.testing.assert_allclose(np.linalg.norm(pts - centre, axis=1), f["radius_cm"])
            np.testing.assert_allclose((pts - centre) @ axis, 0.0, atol=1e-9)
        o = e["arrows"][0]["pose"]["orientation"]  # identity: the arrow points along +x
        x = Rotation.from_quat([o["x"], o["y"], o["z"], o["w"]]).apply([1.0, 0.0, 0.0])
        np.testing.assert_allclose(x, axis / np.linalg.norm(axis), atol=1e-12)
        assert f"joint {f['joint']}" in e["texts"][0]["text"]


def test_cli_writes_the_session_file_and_replaces_only_its_own(session: Path) -> None:
    r = runner.invoke(app, ["viz", str(session)])
    assert r.exit_code == 0, r.output
    assert "metres" in r.output and (session / "viz.mcap").is_file()
    r = runner.invoke(app, ["viz", str(session)])  # its own file: replaced
    assert r.exit_code == 0, r.output
    mine = session / "mine.mcap"
    mine.write_bytes(b"a user's file")
    r = runner.invoke(app, ["viz", str(session), "--out", str(mine)])
    assert r.exit_code == 1 and "not written by `pipeline viz`" in r.output
    assert len(r.output.strip().splitlines()) == 1
    assert mine.read_bytes() == b"a user's file"
    rec = (session / "recording.mcap").read_bytes()
    r = runner.invoke(app, ["viz", str(session), "--out", str(session / "recording.mcap")])
    assert r.exit_code == 1 and (session / "recording.mcap").read_bytes() == rec


def test_cli_refuses_bad_q_in_one_line(session: Path) -> None:
    for q, says in (("1 2", "expected 6 values"), ("1 2 3 4 5 nan", "finite")):
        r = runner.invoke(app, ["viz", str(session), "--q", q])
        assert r.exit_code == 1 and says in r.output, r.output
        assert len(r.output.strip().splitlines()) == 1


def test_stale_signature_or_damaged_stage_is_refused(
    identified_session: Path, tmp_path: Path
) -> None:
    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    feats = stage_path(d, "features")
    feats.write_bytes(feats.read_bytes()[:-100])  # truncated: the signature no longer matches
    r = runner.invoke(app, ["viz", str(d)])
    assert r.exit_code == 1 and "signature.json" in r.output, r.output
    assert not (d / "viz.mcap").exists()


def test_prismatic_joint_is_a_line_of_translation(tmp_path_factory: pytest.TempPathFactory) -> None:
    src = small_session(tmp_path_factory, robot="scara")
    d = tmp_path_factory.mktemp("scara") / "s"
    shutil.copytree(src, d)
    identify(d, report=False)
    path = viz(d).path
    (scene,) = [m for _, c, m in read_viz(path) if c.topic == "/features"]
    feats = {f["joint"]: f for f in read_table(stage_path(d, "features")).to_pylist()}
    (quill,) = [j for j, f in feats.items() if f["type"] == "prismatic"]
    (e,) = [e for e in scene["entities"] if e["id"] == f"joint_{quill}"]
    a, b = (np.array([p["x"], p["y"], p["z"]]) * 100.0 for p in e["lines"][0]["points"])
    f = feats[quill]
    np.testing.assert_allclose(np.linalg.norm(b - a), f["travel_cm"])
    np.testing.assert_allclose((b - a) / f["travel_cm"], [f["axis_x"], f["axis_y"], f["axis_z"]])
    for schema, _, msg in read_viz(path):
        jsonschema.Draft202012Validator(strict(json.loads(schema.data))).validate(msg)


def test_refused_while_another_run_holds_the_session(session: Path, tmp_path: Path) -> None:
    with locked_elsewhere(session):
        r = runner.invoke(app, ["viz", str(session), "--out", str(tmp_path / "v.mcap")])
    assert r.exit_code == 1 and "another pipeline run" in r.output, r.output
    assert not (tmp_path / "v.mcap").exists()


def test_a_pose_set_has_a_named_topic(tmp_path: Path) -> None:
    """Issue 44: a pose set's points went to ``/measured/joint_-2`` (its table sweep id)."""
    from pipeline.rig.simulate import SimulationOptions, simulate_session

    d = tmp_path / "poses"
    simulate_session(d, SimulationOptions(sensor="tracker", poses=30, sweeps=False, check=5))
    identify(d, report=False)
    topics = {c.topic for _, c, _ in read_viz(viz(d).path)}
    measured = {t for t in topics if t.startswith("/measured/")}
    assert measured == {"/measured/poses", "/measured/check"}, measured
