"""``fk --json`` at full precision, ``fk --q-file`` (Arrow or CSV, many configurations)
and option choices in any case (issue 30, item 6)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.ipc as ipc
import pytest
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, EXIT_USAGE, app
from pipeline.control.session import session_controller

Q = [[0.0, -90.0, 90.0, 0.0, 0.0, 0.0], [12.5, -71.25, 133.0, -40.0, 35.0, 290.0]]
COLUMNS = [f"q{i}_deg" for i in range(1, 7)]


def _write_arrow(path: Path, table: pa.Table) -> None:
    with ipc.new_file(str(path), table.schema) as w:
        w.write_table(table)


def _csv(path: Path, rows: list[list[float]]) -> Path:
    path.write_text(",".join(COLUMNS) + "\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows))
    return path


def test_fk_json_is_full_precision(robot3_identified: Path) -> None:
    r = CliRunner().invoke(app, ["fk", str(robot3_identified), "--q", "10 -80 100 5 20 30",
                                 "--json"])  # fmt: skip
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    pose = session_controller(robot3_identified).pose([10, -80, 100, 5, 20, 30])
    assert out["xyz_cm"] == pose.xyz_cm.tolist()  # bit for bit: JSON floats round-trip
    assert out["matrix"] == pose.matrix.tolist() and out["outside_limits"] == []


@pytest.mark.parametrize("kind", ["csv", "arrow"])
def test_fk_q_file_equals_one_call_per_configuration(
    robot3_identified: Path, tmp_path: Path, kind: str
) -> None:
    """Before: one configuration per call (200 calls took 113-308 s). The poses of a file
    are those of single calls bit for bit; the flange at 290° (limits ±266°) is named."""
    if kind == "csv":
        f = _csv(tmp_path / "q.csv", Q)
    else:
        f = tmp_path / "q.arrow"
        _write_arrow(f, pa.table({c: [r[k] for r in Q] for k, c in enumerate(COLUMNS)}))
    r = CliRunner().invoke(app, ["fk", str(robot3_identified), "--q-file", str(f), "--json"])
    assert r.exit_code == 0, r.output
    poses = json.loads(r.stdout)["poses"]
    ctl = session_controller(robot3_identified)
    for row, got in zip(Q, poses, strict=True):
        one = ctl.pose(row)
        assert got["matrix"] == one.matrix.tolist() and got["rpy_deg"] == one.rpy_deg.tolist()
    assert [p["outside_limits"] for p in poses] == [[], ["flange"]]
    assert "1 configuration(s) outside joint limits" in r.stderr


def test_fk_out_feeds_ik_targets(robot3_identified: Path, tmp_path: Path) -> None:
    """fk --out writes an ik --targets input: ik then puts the tool back on those poses."""
    rows = Q[:1] + [[20.0, -60.0, 120.0, 10.0, 30.0, 40.0]]
    f = _csv(tmp_path / "q.csv", rows)
    poses, joints = tmp_path / "poses.arrow", tmp_path / "joints.arrow"
    runner = CliRunner()
    r = runner.invoke(app, ["fk", str(robot3_identified), "--q-file", str(f), "--out", str(poses)])
    assert r.exit_code == 0 and f"wrote {poses}: 2 poses" in r.stdout, r.output
    r = runner.invoke(app, ["ik", str(robot3_identified), "--targets", str(poses),
                            "--out", str(joints)])  # fmt: skip
    assert r.exit_code == 0, r.output
    with pa.OSFile(str(joints), "rb") as fh:
        solved = ipc.open_file(fh).read_all()
    q = np.column_stack([solved.column(c).to_numpy() for c in COLUMNS])
    ctl = session_controller(robot3_identified)
    with pa.OSFile(str(poses), "rb") as fh:
        wanted = ipc.open_file(fh).read_all()
    for k in range(len(rows)):
        p = ctl.pose(q[k])
        assert np.allclose(p.xyz_cm, [wanted.column(c)[k].as_py() for c in ("x_cm", "y_cm",
                           "z_cm")], atol=1e-6)  # fmt: skip
    r = runner.invoke(app, ["fk", str(robot3_identified), "--q-file", str(f), "--out", str(poses)])
    assert r.exit_code == EXIT_REFUSED and "--force" in r.stderr  # never overwritten silently


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("q1_deg,q2_deg\n1,2\n", "missing column(s) q3_deg"),
        (",".join(COLUMNS) + "\n1,2,3,4,5,x\n", "column 'q6_deg' is not numeric"),
        (",".join(COLUMNS) + "\n", "no rows"),
        (",".join(COLUMNS) + "\n1,2,3,4,5,nan\n", "column 'q6_deg' has 1 value(s) that are not"),
        (",".join(COLUMNS) + "\n1,2,3,4,5,\n1,2,3,4,5,6\n", "column 'q6_deg' has 1 null(s)"),
    ],
)
def test_fk_q_file_refuses_bad_files_in_one_line(
    robot3_identified: Path, tmp_path: Path, content: str, message: str
) -> None:
    f = tmp_path / "q.csv"
    f.write_text(content)
    r = CliRunner().invoke(app, ["fk", str(robot3_identified), "--q-file", str(f), "--json"])
    assert r.exit_code == EXIT_REFUSED, r.output
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_fk_needs_one_source(robot3_identified: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    r = runner.invoke(app, ["fk", "puma560"])
    assert r.exit_code == EXIT_USAGE and "'--q' / '--q-file'" in r.stderr
    f = _csv(tmp_path / "q.csv", Q)
    r = runner.invoke(app, ["fk", "puma560", "--q-file", str(f)])
    assert r.exit_code == EXIT_REFUSED and "--q-file needs --out or --json" in r.stderr
    r = runner.invoke(app, ["fk", "puma560", "--q-file", str(f), "--json"])  # a design model
    assert r.exit_code == 0 and len(json.loads(r.stdout)["poses"]) == 2


def test_choices_take_any_case(robot3_identified: Path, tmp_path: Path) -> None:
    """Before: `--format URDF` refused with exit 1. Now any case; a wrong value is a usage
    error (exit 2) listing the choices."""
    runner = CliRunner()
    out = tmp_path / "r.urdf"
    r = runner.invoke(app, ["export", str(robot3_identified), "--format", "URDF",
                            "--frame", "Design-Base", "--out", str(out)])  # fmt: skip
    assert r.exit_code == 0 and out.is_file(), r.output
    r = runner.invoke(app, ["ik", str(robot3_identified), "--pose", "40", "20", "60", "180",
                            "0", "90", "--method", "JACOBI"])  # fmt: skip
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["export", str(robot3_identified), "--format", "xyz"])
    assert r.exit_code == EXIT_USAGE and "'urdf', 'dh', 'mdh', 'json'" in r.stderr
    r = runner.invoke(app, ["simulate", str(tmp_path / "s"), "--sensor", "radar"])
    assert r.exit_code == EXIT_USAGE and "'sonic', 'tracker'" in r.stderr
