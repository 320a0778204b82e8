"""Issue 29: a laser-tracker file of a coupled arm imports as it is. The controller's
readings become joint values through the robot description's ``[coupling]`` wherever the
import asks which joint moves; three reflectors on the tool, measured at every stop, are
each one point of the last link that the whole-chain fit ties the sweeps through; home a
whole turn away is home."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from coupled_table import PUMA, coupled_robot, tracker_file, tracker_map

from pipeline.contract.channels import POINT_CHANNELS
from pipeline.contract.mcap_read import read_mcap
from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.rig.audit import audit
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table


def _rows(path: Path) -> np.ndarray:
    return np.loadtxt(path, skiprows=1)


def _description(session: Path) -> dict:
    content = read_mcap(session / "recording.mcap", POINT_CHANNELS, "re-import")
    return content.messages["/robot/description"][0][1]  # type: ignore[no-any-return]


@pytest.fixture(scope="module")
def coupled(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """The coupled file imported with the right ``[coupling]`` and identified; the file,
    the robot description and the session (the simulator's truth copied in for the audit)."""
    d = tmp_path_factory.mktemp("coupled")
    robot = coupled_robot(d)
    src, sim = tracker_file(d, robot)
    import_file(src, "table", robot, d / "s", tracker_map(d))
    shutil.copy(sim / "rig-truth.json", d / "s" / "rig-truth.json")
    identify(d / "s", report=False)
    return src, robot, d / "s"


def test_coupled_file_imports_readings_as_readings(coupled: tuple[Path, Path, Path]) -> None:
    src, _, session = coupled
    rows = _rows(src)
    sweep2 = rows[(rows[:, 1] != rows[0, 1])]  # the shoulder's sweep: its readings move
    assert np.ptp(sweep2[:, 2]) > 200.0  # ... and so does the elbow's reading, coupled
    desc = _description(session)
    plan = desc["plan"]
    assert [s["n_points"] for s in plan["sweeps"]] == [7, 6, 6, 6, 6, 6]  # home joins sweep 1
    assert plan["tool_targets"] == ["a", "b", "c"] and plan["tool_target"] == "a"
    content = read_mcap(session / "recording.mcap", POINT_CHANNELS, "re-import")
    recorded = {tuple(m["q_encoder"]) for _, m in content.messages["/robot/joint_state"]}
    assert recorded == {tuple(r) for r in rows[:, :6]}  # the file's readings, not joint values
    assert {m["target"] for _, m in content.messages["/points"] if m["sweep"] == "tool"} == {
        "a",
        "b",
        "c",
    }


def test_coupled_file_identifies_exactly(coupled: tuple[Path, Path, Path]) -> None:
    _, _, session = coupled
    names = read_table(stage_path(session, "refine")).column("name").to_pylist()
    points = {n.rsplit(".", 1)[0] for n in names if not n.startswith("joint")}
    assert points == {"tool", "tool/b", "tool/c"}  # each reflector one point in every sweep
    r = audit(session, configurations=500)
    assert r.signature.max_position_cm <= 1e-6, r.signature
    assert r.signature.max_orientation_deg <= 1e-6, r.signature
    fit = read_table(stage_path(session, "validation")).column("error_cm").to_numpy()
    assert len(fit) == 37 + 1 and fit.max() <= 1e-6  # every row's tool reflector a


def test_ik_returns_the_controllers_readings(coupled: tuple[Path, Path, Path]) -> None:
    from pipeline.control.poses import solve_pose
    from pipeline.control.session import session_controller

    src, robot_toml, session = coupled
    ctl = session_controller(session)
    rows = _rows(src)[:, :6]
    for readings in rows[[8, 10, 12]]:  # stops of the shoulder's sweep
        pose = ctl.pose(readings)
        r = solve_pose(session, [*pose.xyz_cm, *pose.rpy_deg], near=readings + 2.0)
        assert r.converged
        np.testing.assert_allclose(r.q, readings, atol=1e-6)
        joints = ctl.robot.joints_from_readings(readings)
        assert abs(joints[2] - readings[2]) > 10.0  # readings, not the joint values


def test_wrong_coupling_names_the_sweep_that_disagrees(tmp_path: Path) -> None:
    """2 % wrong (elbow = reading 3 − 1.02 × reading 2): refused at the default held-joint
    tolerance; with it raised to 10°, the fit ties the sweeps through the reflectors on the
    tool and the verdict names sweep 2, where the wrong coupling moves the elbow."""
    right = coupled_robot(tmp_path)
    src, _ = tracker_file(tmp_path, right)
    wrong = coupled_robot(tmp_path, -1.02)
    with pytest.raises(ArmsigError, match=r"no single joint moves here .*through the coupling"):
        import_file(src, "table", wrong, tmp_path / "w0", tracker_map(tmp_path))
    import_file(src, "table", wrong, tmp_path / "w", tracker_map(tmp_path, "tolerance = 10"))
    identify(tmp_path / "w", report=False)
    v = read_table(stage_path(tmp_path / "w", "verdict")).to_pylist()[0]
    assert v["verdict"] in ("CHECK", "FAIL")
    sweeps = [r for r in v["reasons"] if r.startswith("the sweeps disagree")]
    assert len(sweeps) == 1 and "sweep 2:" in sweeps[0], v["reasons"]
    assert "sweep 1:" not in sweeps[0] and "[coupling]" in sweeps[0]


def test_sweeps_select_holds_joint_values(tmp_path: Path) -> None:
    """``[[sweeps.select]]`` chooses each sweep by its held joints' values: in the shoulder's
    sweep the elbow holds while its reading moves."""
    from pipeline.robots.description import load_description

    robot = coupled_robot(tmp_path)
    src, _ = tracker_file(tmp_path, robot)
    home = load_description(robot).joints_from_readings(_rows(src)[-1, :6])
    select = {j: {k: float(home[k - 1]) for k in range(1, 7) if k != j} for j in range(1, 7)}
    out = import_file(src, "table", robot, tmp_path / "s", tracker_map(tmp_path, select=select))
    assert [int((out.rows.sweep == j).sum()) for j in range(1, 7)] == [7] * 6  # and home
    assert not (out.rows.sweep < 0).any()  # no row left over as a validation configuration


def test_decoupled_file_with_a_coupled_description_is_refused(tmp_path: Path) -> None:
    """The issue's hand-decoupled file (readings = joint values) read with the coupled
    description: the elbow's joint value moves in the shoulder's sweep."""
    src, _ = tracker_file(tmp_path, PUMA)
    with pytest.raises(ArmsigError, match=r"no single joint moves here") as err:
        import_file(src, "table", coupled_robot(tmp_path), tmp_path / "s", tracker_map(tmp_path))
    assert "[coupling]" in str(err.value)


@pytest.mark.parametrize("coupling", [False, True])
def test_home_a_turn_away_is_home(tmp_path: Path, coupling: bool) -> None:
    """No row reads home exactly; the first reads joint 6 at home + 360°: it is the tool
    measurement (no fallback, no warning), recorded with q^s on home's turn."""
    robot = coupled_robot(tmp_path) if coupling else PUMA
    src, _ = tracker_file(tmp_path, robot, home_turned=True)
    rows = _rows(src)[:, :6]
    out = import_file(src, "table", robot, tmp_path / "s", tracker_map(tmp_path))
    assert out.tool.warning is None, out.tool.warning
    assert list(out.tool.rows) == [0]
    home = rows[0] - [0, 0, 0, 0, 0, 360.0]
    np.testing.assert_allclose(out.tool.signature_q, home)
    desc = _description(tmp_path / "s")
    np.testing.assert_allclose(desc["signature_q"], home)
    content = read_mcap(tmp_path / "s" / "recording.mcap", POINT_CHANNELS, "re-import")
    states = content.messages["/robot/joint_state"]
    np.testing.assert_allclose([m["q_encoder"] for _, m in states if m["sweep"] == "tool"], [home])


def test_import_warns_in_one_line_and_raises_no_python_warning(tmp_path: Path) -> None:
    """The fallback when no row is at home (the SScanSS-2 file without its home rows) is one
    ``warning:`` line of the command; the import path raises no Python warning."""
    from import_data import TWO_LINK, sscanss2_text
    from typer.testing import CliRunner

    from pipeline.cli import app

    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, [[-150, -50, 50, 150], [-120, -40, 40, 120]]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        args = ["import", str(src), "--format", "sscanss2", "--robot", str(TWO_LINK)]
        r = CliRunner().invoke(app, [*args, str(tmp_path / "s")])
    assert r.exit_code == 0, r.output
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "warning: two.txt: no row has every joint at home"
    )
