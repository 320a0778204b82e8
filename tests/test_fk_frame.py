"""Issue 29, item 7: `fk SESSION --frame sensor|design-base`, the default stated in the
help and in the output. In the sensor frame the signature's tool point at a measured
configuration is the model's prediction of that measurement (stage validation)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from import_data import TABLE, sscanss2_text
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.control.poses import tool_pose
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.signature.file import FILE_NAME
from pipeline.signature.session import load_session_signature
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table

runner = CliRunner()
VALUES = [[0, 100, 200, 300, 400, 500], [-180, -108, -36, 36, 108, 180],
          [-200, -120, -40, 40, 120, 200], [-200, -120, -40, 40, 120, 200]]  # fmt: skip


@pytest.fixture(scope="module")
def table_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("fk_frame")
    src = tmp / "table.txt"
    src.write_text(sscanss2_text(TABLE, VALUES, digits=15))
    d = tmp / "s"
    import_file(src, "sscanss2", TABLE, d)
    identify(d, report=False)
    return d


def test_the_sensor_frame_predicts_the_measurements(table_session: Path) -> None:
    rows = read_table(stage_path(table_session, "validation")).to_pylist()
    row = next(r for r in rows if r["sweep"] == 3 and r["step"] == 2)  # y stage at -40 mm
    q = [0.0, 0.0, -4.0, 0.0]
    p = tool_pose(table_session, q, frame="sensor").xyz_cm
    assert np.allclose(p, [row[f"model_{a}_cm"] for a in "xyz"], atol=1e-9)
    assert np.allclose(p, [row[f"{a}_cm"] for a in "xyz"], atol=1e-6)  # noiseless file


@pytest.mark.parametrize("design", [False, True])
def test_the_two_frames_differ_by_the_design_alignment(table_session: Path, design: bool):
    sig = load_session_signature(table_session / FILE_NAME)
    q = [10.0, 30.0, 5.0, -5.0]
    base = tool_pose(table_session, q, design=design).matrix  # the default
    sensor = tool_pose(table_session, q, design=design, frame="sensor").matrix
    assert np.allclose(sig.sensor_from_design_base @ base, sensor, atol=1e-9)


def test_the_output_and_the_help_name_the_frame(table_session: Path) -> None:
    r = runner.invoke(app, ["fk", str(table_session), "--q", "0 0 -4 0"])
    assert r.exit_code == 0 and r.stdout.startswith("frame   = design-base\n"), r.output
    r = runner.invoke(app, ["fk", str(table_session), "--q", "0 0 -4 0", "--frame", "sensor",
                            "--json"])  # fmt: skip
    assert r.exit_code == 0 and json.loads(r.stdout)["frame"] == "sensor", r.output
    r = runner.invoke(app, ["fk", "puma560", "--q", "0 0 0 0 0 0"])
    assert r.exit_code == 0 and r.stdout.startswith("frame   = base\n"), r.output
    r = runner.invoke(app, ["fk", "--help"], env={"COLUMNS": "200"})
    assert "--frame" in r.stdout and "design-base (default" in " ".join(r.stdout.split())


def test_sensor_frame_refused_where_it_has_no_meaning(table_session: Path, tmp_path: Path):
    r = runner.invoke(app, ["fk", "puma560", "--q", "0 0 0 0 0 0", "--frame", "sensor"])
    assert r.exit_code == 1 and "--frame sensor needs an identified session" in r.output
    qf = tmp_path / "q.csv"
    qf.write_text("q1_cm,q2_deg,q3_cm,q4_cm\n0,0,0,0\n")
    r = runner.invoke(app, ["fk", str(table_session), "--q-file", str(qf), "--out",
                            str(tmp_path / "o.arrow"), "--frame", "sensor"])  # fmt: skip
    assert r.exit_code == 1 and "--out writes an `ik --targets` input" in r.output, r.output


def test_fk_of_a_description_names_its_tool_point(tmp_path: Path) -> None:
    """Issue 44: ``fk ROBOT`` was documented as the design flange, but its pose includes
    the description's ``[tool]``. The output names the point, and the pose is the last
    D-H frame times that tool."""
    from pipeline.kinematics.chain import link_frames
    from pipeline.robots import get_robot

    text = (Path(__file__).resolve().parents[1] / "pipeline/robots/data/scara.toml").read_text()
    desc = tmp_path / "scara_tool.toml"
    desc.write_text(text + "\n[tool]\nxyz_cm = [0.0, 0.0, 8.0]\nrpy_deg = [0.0, 0.0, 0.0]\n")
    r = runner.invoke(app, ["fk", str(desc), "--q", "10 20 5 30", "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["point"].startswith("the design tool") and "[tool]" in out["point"]
    robot = get_robot(desc)
    q = np.radians([10.0, 20.0, 0.0, 30.0])
    q[2] = 5.0
    last = link_frames(robot.design_chain(), q[None])[0, -2]  # the last D-H frame
    want = last @ robot.tool.matrix()
    np.testing.assert_allclose(out["matrix"], want, atol=1e-12)
    assert np.linalg.norm(np.asarray(out["matrix"])[:3, 3] - last[:3, 3]) > 7.9
    r = runner.invoke(app, ["fk", str(desc), "--q", "10 20 5 30"])
    assert "point   = the design tool" in r.stdout
