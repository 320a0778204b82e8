"""`pipeline plan --sensor camera` (issue 39): images chosen for the camera fit's smallest
predicted tool error, written as the tracker's pose plan and recorded by `simulate --plan`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_cli_errors import assert_one_error as assert_refused
from typer.testing import CliRunner, Result

from pipeline.cli import EXIT_REFUSED, app
from pipeline.cli.options import (
    DISTORTION,
    FOCAL_PX,
    PIXEL_NOISE,
    RESOLUTION,
    distortion_terms,
    resolution_px,
)
from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.planning import write_plan
from pipeline.planning.camera import camera_rig, plan_camera_poses
from pipeline.rig import camera
from pipeline.rig.camera_audit import audit_camera_session
from pipeline.rig.pose_file import read_pose_plan
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots import get_robot
from pipeline.stages.frames import sweep_readings
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table
from pipeline.sweeps import POSES_SWEEP

LENS = ((1280, 960), 1000.0, (-0.12, 0.05, 5e-4, -3e-4, 0.0), 0.2)


def invoke(*args: str) -> Result:
    return CliRunner().invoke(app, list(args))


def assert_one_error(r: Result, *fragments: str) -> None:
    assert_refused(r, EXIT_REFUSED, *fragments)


def test_the_command_line_defaults_are_the_simulators() -> None:
    o = SimulationOptions()
    assert resolution_px(RESOLUTION) == o.resolution_px and FOCAL_PX == o.focal_px
    assert distortion_terms(DISTORTION) == o.distortion and PIXEL_NOISE == o.pixel_noise_px


@pytest.fixture(scope="module", params=["eye-to-hand", "eye-in-hand"])
def plan(request: pytest.FixtureRequest):
    rig = camera_rig(request.param, camera.DEFAULT_TARGET, *LENS)
    return request.param, plan_camera_poses(get_robot("puma560"), rig, 16, candidates=400)


def test_planned_images_predict_less_error_than_as_many_random_visible_ones(plan) -> None:
    _, p = plan
    assert len(p.q) == 16 and p.unidentified == ()
    assert p.rms_cm < 0.9 * p.random_rms_cm
    assert np.all(np.diff(p.rms_by_size_cm) <= 1e-15)  # each image helps
    lim = get_robot("puma560").limits
    assert ((p.q >= lim[:, 0]) & (p.q <= lim[:, 1])).all()


def test_the_simulator_records_the_plan_and_it_identifies(tmp_path: Path, plan) -> None:
    """Noiseless: the tool point audited to 1e-6 cm; the images the detector keeps at the
    true rig are the plan's poses in its order (``plan_steps``)."""
    setup, p = plan
    robot = get_robot("puma560")
    f = write_plan(tmp_path / "plan.csv", robot, p, sensor=f"camera {setup}")
    assert f"camera {setup}" in f.read_text().splitlines()[0]
    d = tmp_path / "s"
    opts = SimulationOptions(sensor="camera", setup=setup, plan_file=str(f), noiseless=True)
    simulate_session(d, opts)
    truth = json.loads((d / "rig-truth.json").read_text())
    steps = truth["camera"]["dropped_images"]["plan_steps"]
    assert len(steps) >= 14 and steps == sorted(steps)
    identify(d, report=False)
    _, q = sweep_readings(read_table(stage_path(d, "joints")), POSES_SWEEP, 6, robot.prismatic)
    assert np.allclose(q, read_pose_plan(f, robot)[steps], atol=1e-6)
    assert audit_camera_session(d).tool_position_cm <= 1e-6


def test_the_command_writes_the_plan_and_prints_both_predictions(tmp_path: Path) -> None:
    out = tmp_path / "p.csv"
    args = ["plan", str(out), "--robot", "puma560", "--sensor", "camera", "--setup"]
    r = invoke(*args, "eye-in-hand", "--poses", "12", "--candidates", "200", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["poses"] == 12 and doc["predicted_rms_cm"] <= doc["random_predicted_rms_cm"]
    assert read_pose_plan(out, get_robot("puma560")).shape == (12, 6)
    r = invoke(*args, "eye-to-hand", "--poses", "12", "--candidates", "200", "--force")
    assert r.exit_code == 0 and "12 images, predicted RMS tool error" in r.stdout
    assert "as many random visible poses" in r.stdout


@pytest.mark.parametrize(
    ("extra", "fragments"),
    [
        (["--sensor", "camera", "--focal-px", "10", "--candidates", "5", "--poses", "5"],
         ["sees the target in 0 of", "shorter focal length"]),
        (["--sensor", "camera", "--sweeps"], ["not a camera's images"]),
        (["--sensor", "camera", "--sigma-mm", "0.02"], ["--sigma-mm is a tracker's"]),
        (["--setup", "eye-in-hand"], ["--setup is for --sensor camera"]),
        (["--pixel-noise", "0.3", "--sweeps"], ["--pixel-noise is for --sensor camera"]),
        (["--sensor", "camera", "--resolution", "big"], ["--resolution must be WIDTHxHEIGHT"]),
    ],
)  # fmt: skip
def test_bad_input_is_one_line(tmp_path: Path, extra: list[str], fragments: list[str]) -> None:
    out = tmp_path / "p.csv"
    assert_one_error(invoke("plan", str(out), "--robot", "puma560", *extra), *fragments)
    assert not out.exists()


def test_plan_from_a_camera_session_chooses_among_its_images(tmp_path: Path) -> None:
    """``plan --from`` a camera session: its most informative images, their readings in the
    order chosen, predicting less than its first as many; the plan recorded again."""
    robot = get_robot("puma560")
    d = tmp_path / "s"
    simulate_session(d, SimulationOptions(sensor="camera", setup="eye-in-hand", poses=24))
    identify(d, report=False)
    out = tmp_path / "p.csv"
    r = invoke("plan", str(out), "--from", str(d), "--poses", "12", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    steps = doc["session_steps"]
    assert len(set(steps)) == 12 and doc["predicted_rms_cm"] < doc["random_predicted_rms_cm"]
    _, q = sweep_readings(read_table(stage_path(d, "joints")), POSES_SWEEP, 6, robot.prismatic)
    assert np.allclose(read_pose_plan(out, robot), q[steps], atol=1e-6)
    again = tmp_path / "t"
    simulate_session(again, SimulationOptions(sensor="camera", setup="eye-in-hand",
                                              plan_file=str(out), noiseless=True))  # fmt: skip
    identify(again, report=False)
    assert audit_camera_session(again).tool_position_cm <= 1e-6
    assert_one_error(invoke("plan", str(out), "--from", str(d), "--poses", "25", "--force"),
                     "more images asked than the session holds")  # fmt: skip
    assert_one_error(invoke("plan", str(out), "--from", str(d), "--setup", "eye-in-hand"),
                     "--setup with --from")  # fmt: skip
    empty = tmp_path / "e"
    empty.mkdir()
    assert_one_error(invoke("plan", str(out), "--from", str(empty), "--sensor", "camera"),
                     "not an identified camera session")  # fmt: skip


def test_a_plan_the_camera_cannot_see_is_refused_in_one_line(tmp_path: Path) -> None:
    robot = get_robot("puma560")
    f = tmp_path / "plan.csv"
    header = "step," + ",".join(f"{j.name}_{j.unit}" for j in robot.joints)
    f.write_text(header + "\n" + "\n".join(f"{k},0,0,0,0,0,0" for k in range(6)) + "\n")
    opts = SimulationOptions(sensor="camera", setup="eye-to-hand", plan_file=str(f))
    with pytest.raises(ArmsigError, match="sees the target in 0 of the plan's 6 poses"):
        simulate_session(tmp_path / "s", opts)
    with pytest.raises(ArmsigError, match="--plan and --poses both"):
        simulate_session(tmp_path / "t", SimulationOptions(sensor="camera", plan_file=str(f),
                                                           poses=10))  # fmt: skip
