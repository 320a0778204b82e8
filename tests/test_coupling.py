"""Coupled joints: joint = C · reading + offset (schemas/robot_description.md [coupling])."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.control.controller import solve_poses
from pipeline.control.session import session_controller
from pipeline.errors import RobotDescriptionError
from pipeline.identify import identify
from pipeline.rig.audit import audit
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots.description import (
    description_from_dict,
    description_to_dict,
    load_description,
)
from pipeline.stages.recording import read_recording

SCARA = Path(__file__).resolve().parent.parent / "pipeline" / "robots" / "data" / "scara.toml"
# elbow = reading 2 + 0.1 · reading 1 + 2 deg; roll = reading 4 - 0.2 · reading 2 - 5 deg
COUPLING = """
[coupling]
matrix = [[1.0, 0.0, 0.0, 0.0], [0.1, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -0.2, 0.0, 1.0]]
offset = [0.0, 2.0, 0.0, -5.0]
"""


@pytest.fixture(scope="module")
def coupled_toml(tmp_path_factory: pytest.TempPathFactory) -> Path:
    p = tmp_path_factory.mktemp("coupled") / "scara_coupled.toml"
    p.write_text(SCARA.read_text().replace('name = "scara"', 'name = "scara_coupled"') + COUPLING)
    return p


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-150, 150), min_size=4, max_size=4))
def test_readings_round_trip(coupled_toml: Path, r: list[float]) -> None:
    robot = load_description(coupled_toml)
    q = robot.joints_from_readings(np.array([r]))
    np.testing.assert_allclose(robot.readings_from_joints(q), [r], atol=1e-9)
    assert q[0, 1] == pytest.approx(r[1] + 0.1 * r[0] + 2.0)


def test_description_round_trips_with_coupling(coupled_toml: Path) -> None:
    robot = load_description(coupled_toml)
    again = description_from_dict(description_to_dict(robot))
    assert again == robot and again.coupling is not None


def test_singular_coupling_refused(coupled_toml: Path) -> None:
    text = coupled_toml.read_text().replace("[0.1, 1.0, 0.0, 0.0]", "[1.0, 0.0, 0.0, 0.0]")
    bad = coupled_toml.with_name("singular.toml")
    bad.write_text(text)
    with pytest.raises(RobotDescriptionError, match="coupling: field 'matrix' is not invertible"):
        load_description(bad)


@pytest.fixture(scope="module")
def coupled_session(coupled_toml: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("coupled-exact")
    opts = SimulationOptions(robot=str(coupled_toml), seed=1, noiseless=True, points=12, repeats=1)
    simulate_session(d, opts)
    identify(d, report=False)
    return d


def test_coupled_noiseless_session_is_exact(coupled_session: Path) -> None:
    rec = read_recording(coupled_session / "recording.mcap")
    sweep1 = rec.q_encoder[rec.joint_sweep == 1]
    assert np.ptp(sweep1[:, 1]) > 1.0  # the recorded elbow reading moves with joint 1
    r = audit(coupled_session, configurations=200)
    assert r.signature.max_position_cm <= 1e-6, r.signature
    assert r.signature.max_orientation_deg <= 1e-7, r.signature


def test_control_returns_readings(coupled_session: Path) -> None:
    ctl = session_controller(coupled_session)
    readings = np.array([30.0, 40.0, 10.0, 20.0])
    pose = ctl.pose(readings)
    q, res = solve_poses(ctl, pose.xyz_cm[None], pose.rpy_deg[None], near=readings + 2.0)
    assert res.converged[0]
    np.testing.assert_allclose(q[0], readings, atol=1e-6)
    joints = ctl.robot.joints_from_readings(readings)
    assert not np.allclose(joints, readings)  # the solve's joint values differ from readings
