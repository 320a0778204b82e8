"""The functions behind ``fk``, ``ik``, ``status`` and ``show`` (issue 31): importable,
free of typer and of exit codes, and what the commands print."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
import pytest
from typer.testing import CliRunner

from pipeline.cli import EXIT_NOT_REACHED, app
from pipeline.control.poses import solve_pose, solve_targets, tool_pose
from pipeline.control.session import session_controller
from pipeline.control.targets import TARGET_COLUMNS
from pipeline.errors import ArmsigError
from pipeline.robots import get_robot
from pipeline.robots.fk import design_pose
from pipeline.stages.inspection import session_status, stage_table

Q = [10.0, -80.0, 100.0, 5.0, 20.0, 30.0]  # deg, inside the Puma's limits
runner = CliRunner()


def test_tool_pose_of_a_session_and_of_a_robot(identified_session: Path) -> None:
    want = session_controller(identified_session).pose(Q).matrix
    np.testing.assert_array_equal(tool_pose(identified_session, Q).matrix, want)
    np.testing.assert_array_equal(
        tool_pose("puma560", Q).matrix, design_pose(get_robot("puma560"), Q).matrix
    )
    assert tool_pose("puma560", [*Q[:2], 400.0, *Q[3:]]).outside_limits == ("elbow",)


def test_solve_pose_round_trips_and_is_what_ik_json_prints(identified_session: Path) -> None:
    pose = tool_pose(identified_session, Q)
    target = [float(v) for v in (*pose.xyz_cm, *pose.rpy_deg)]
    r = solve_pose(identified_session, target, near=Q)
    assert r.converged and r.status == "converged" and r.tool == "signature"
    np.testing.assert_allclose(r.q, Q, atol=1e-4)
    near = " ".join(map(str, Q))
    out = runner.invoke(
        app, ["ik", str(identified_session), "--pose", *map(repr, target), "--near", near, "--json"]
    )
    assert out.exit_code == 0, out.output
    assert json.loads(out.stdout) == r.to_dict()
    far = solve_pose(identified_session, [500.0, 0, 0, 0, 0, 0])
    assert not far.converged  # an answer, not an error
    cli = runner.invoke(app, ["ik", str(identified_session), "--pose", "500", *["0"] * 5])
    assert cli.exit_code == EXIT_NOT_REACHED and "q = " in cli.stdout


def test_solve_targets_writes_the_joints(identified_session: Path, tmp_path: Path) -> None:
    pose = tool_pose(identified_session, Q)
    values = [*pose.xyz_cm, *pose.rpy_deg]
    table = pa.table(
        {c: [v, 500.0 if c == "x_cm" else 0.0] for c, v in zip(TARGET_COLUMNS, values, strict=True)}
    )
    with ipc.new_file(str(tmp_path / "t.arrow"), table.schema) as w:
        w.write_table(table)
    r = solve_targets(identified_session, tmp_path / "t.arrow", tmp_path / "q.arrow", near=Q)
    assert (r.targets, r.converged, r.failed) == (2, 1, 1)
    assert r.summary.startswith("1 of 2 targets converged")
    keys = {"targets", "converged", "failed", "out", "method", "tool"}
    assert set(r.to_dict()) == keys | {"verdict", "verdict_warning"}


def test_session_status_is_what_status_prints(identified_session: Path) -> None:
    states = session_status(identified_session)
    assert {s.state for s in states} == {"fresh"} and states[-1].name == "signature"
    out = runner.invoke(app, ["status", str(identified_session), "--json"])
    assert json.loads(out.stdout) == [
        {"name": s.name, "state": s.state, "reason": s.reason} for s in states
    ]


def test_stage_table_selects_columns_and_refuses_unknown_ones(identified_session: Path) -> None:
    st = stage_table(identified_session, "features", ["joint", "radius_cm"])
    assert st.table.column_names == ["joint", "radius_cm"] and st.table.num_rows > 0
    assert st.provenance["stage"] == "features"
    with pytest.raises(ArmsigError, match="no column 'nope'; expected joint"):
        stage_table(identified_session, "features", ["nope"])
    with pytest.raises(ArmsigError, match="no such stage output"):
        stage_table(identified_session, "nostage")
    # The command prints nothing on stdout before refusing a column.
    r = runner.invoke(app, ["show", str(identified_session), "features", "--columns", "joint,x"])
    assert r.exit_code == 1 and r.stdout == "" and "no column 'x'" in r.stderr
