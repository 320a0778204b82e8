"""`pipeline import`: each format becomes a point session per the contract (schemas/mcap/)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from import_data import TWO_LINK, TWO_LINK_MAP, TWO_LINK_VALUES, sscanss2_text, two_link_table
from mcap.reader import make_reader

from pipeline.contract.channels import POINT_CHANNELS
from pipeline.contract.digest import file_sha256
from pipeline.contract.mcap_read import read_mcap
from pipeline.errors import ArmsigError
from pipeline.importers import import_file
from pipeline.importers.write import SOURCE_METADATA


def _read(session: Path) -> dict[str, list[dict]]:
    content = read_mcap(session / "recording.mcap", POINT_CHANNELS, "re-import")
    return {t: [m for _, m in msgs] for t, msgs in content.messages.items()}


def _metadata(session: Path) -> dict[str, str]:
    with (session / "recording.mcap").open("rb") as fh:
        for rec in make_reader(fh).iter_metadata():
            if rec.name == SOURCE_METADATA:
                return dict(rec.metadata)
    raise AssertionError("no armsig.source metadata")


@pytest.mark.parametrize("sep", ["\t", ","])
def test_sscanss2_session(tmp_path: Path, sep: str) -> None:
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES, sep))
    out = import_file(src, "sscanss2", TWO_LINK, tmp_path / "s")
    msgs = _read(tmp_path / "s")
    desc = msgs["/robot/description"][0]
    assert desc["mode"] == "imported"
    assert msgs["/rig/description"][0]["sensor"] == "points"
    sweeps = {s["joint"]: s for s in desc["plan"]["sweeps"]}
    assert sweeps[1]["n_points"] == 7 and sweeps[2]["q_first"] == -120.0
    assert desc["plan"]["order"] == [1, 2, "tool"]
    # steps ordered by reading, q_commanded = q_encoder = the reading
    j2 = sorted((m["step"], m["q_encoder"][1]) for m in msgs["/robot/joint_state"]
                if m["sweep"] == 2)  # fmt: skip
    assert [q for _, q in j2] == sorted(q for _, q in j2)
    assert all(m["q_commanded"] == m["q_encoder"] for m in msgs["/robot/joint_state"])
    # tool: both rows at home (each joint's 0)
    assert len(out.tool.rows) == 2 and desc["signature_q"] == [0.0, 0.0]
    meta = _metadata(tmp_path / "s")
    assert meta["file"] == "two.txt" and meta["sha256"] == file_sha256(src)
    assert meta["format"] == "sscanss2" and meta["map_sha256"] == ""


def test_table_infer_two_targets_units(tmp_path: Path) -> None:
    src = two_link_table(tmp_path / "two.csv")
    mp = tmp_path / "map.toml"
    mp.write_text(TWO_LINK_MAP)
    import_file(src, "table", TWO_LINK, tmp_path / "s", mp)
    msgs = _read(tmp_path / "s")
    pts = msgs["/points"]
    assert {p["target"] for p in pts} == {"a", "b"}
    js = {(m["sweep"], m["step"]): m["q_encoder"] for m in msgs["/robot/joint_state"]}
    assert js[(2, 0)][1] == pytest.approx(-120.0, abs=1e-9)  # rad -> deg
    a = {(p["sweep"], p["step"]): p for p in pts if p["target"] == "a"}
    b = {(p["sweep"], p["step"]): p for p in pts if p["target"] == "b"}
    assert b[(1, 0)]["z_cm"] - a[(1, 0)]["z_cm"] == pytest.approx(0.05)  # mm -> cm
    assert _metadata(tmp_path / "s")["map_sha256"] == file_sha256(mp)


def test_docs_example_two_targets_identifies(tmp_path: Path) -> None:
    """The docs' example map (two reflectors on the tool of a 2 mm arm, issue 29): both are
    points of the last link in every sweep and the tool measurement, and the arm, below the
    1 cm floor that picks among a nest's targets, identifies from them exactly."""
    from pipeline.identify import identify
    from pipeline.stages.tables import read_table

    src = two_link_table(tmp_path / "two.csv")
    mp = tmp_path / "map.toml"
    mp.write_text(TWO_LINK_MAP)
    import_file(src, "table", TWO_LINK, tmp_path / "s", mp)
    plan = _read(tmp_path / "s")["/robot/description"][0]["plan"]
    assert plan["tool_targets"] == ["a", "b"] and plan["sweeps_measure_tool"]
    identify(tmp_path / "s", report=False)
    names = read_table(tmp_path / "s" / "stages" / "refine.arrow").column("name").to_pylist()
    assert {"tool.x", "tool/b.x"} <= set(names) and not any("sweep" in n for n in names)
    rows = read_table(tmp_path / "s" / "stages" / "validation.arrow").to_pylist()
    assert len(rows) == 7 + 7 + 2 and max(r["error_cm"] for r in rows) <= 1e-9


def test_held_tolerance_is_not_the_duplicate_rule(tmp_path: Path) -> None:
    """A held-joint tolerance above a sweep's step (45° against joint 2's 40° steps) once
    refused the stops as duplicated rows (issue 29); two stops are one configuration only
    within sweeps.duplicate (default: the encoder resolution)."""
    src = two_link_table(tmp_path / "two.csv")
    lines = src.read_text().splitlines()
    body = [f"{x},{1 if k < 7 else 2}" for k, x in enumerate(lines[2:])]
    src.write_text("\n".join([lines[0], lines[1] + ",sweep", *body]) + "\n")
    mp = tmp_path / "map.toml"
    mp.write_text(TWO_LINK_MAP.replace('"infer"', '"sweep"').replace("0.01", "45"))
    out = import_file(src, "table", TWO_LINK, tmp_path / "s", mp)
    assert [int((out.rows.sweep == j).sum()) for j in (1, 2)] == [7, 7]


def test_existing_recording_refused_unless_force(tmp_path: Path) -> None:
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    import_file(src, "sscanss2", TWO_LINK, tmp_path / "s")
    before = (tmp_path / "s" / "recording.mcap").read_bytes()
    with pytest.raises(ArmsigError, match="already holds a recording"):
        import_file(src, "sscanss2", TWO_LINK, tmp_path / "s")
    assert (tmp_path / "s" / "recording.mcap").read_bytes() == before
    import_file(src, "sscanss2", TWO_LINK, tmp_path / "s", force=True)


def test_no_home_row_uses_last_sweep_nearest_home(tmp_path: Path) -> None:
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, [[-150, -50, 50, 150], [-120, -40, 40, 120]]))
    out = import_file(src, "sscanss2", TWO_LINK, tmp_path / "s")
    assert out.tool.warning is not None and "no row has every joint at home" in out.tool.warning
    desc = _read(tmp_path / "s")["/robot/description"][0]
    assert desc["signature_q"] == [0.0, -40.0] and len(out.tool.rows) == 1
    np.testing.assert_array_equal(out.tool.signature_q, [0.0, -40.0])


def test_small_robot_identifies_exactly(tmp_path: Path) -> None:
    """A two-link arm with radii of 1 and 2 mm (SScanSS-2's example scale): its only target
    per sweep is used (no absolute 1 cm floor), and the model error is exact."""
    from pipeline.identify import identify
    from pipeline.stages.tables import read_table

    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES, digits=15))
    import_file(src, "sscanss2", TWO_LINK, tmp_path / "s")
    identify(tmp_path / "s", report=True)
    rows = read_table(tmp_path / "s" / "stages" / "validation.arrow").to_pylist()
    assert len(rows) == 7 + 7 + 2 and {r["role"] for r in rows} == {"fit"}
    assert max(r["error_cm"] for r in rows) <= 1e-9
    report = (tmp_path / "s" / "report" / "report.md").read_text()
    assert "## Validation: model position error on measured points" in report


def test_prismatic_rotary_prismatic_prismatic_identifies_exactly(tmp_path: Path) -> None:
    """SScanSS-2's table layout (P R P P, two prismatic joints in a row, mm-scale target
    offsets) from its design model: the S-Model chain needs nothing more, model error exact."""
    from import_data import TABLE

    from pipeline.identify import identify
    from pipeline.stages.tables import read_table

    values = [[0, 100, 200, 300, 400, 500], [-180, -108, -36, 36, 108, 180],
              [-200, -120, -40, 40, 120, 200], [-200, -120, -40, 40, 120, 200]]  # fmt: skip
    src = tmp_path / "table.txt"
    src.write_text(sscanss2_text(TABLE, values, digits=15))
    import_file(src, "sscanss2", TABLE, tmp_path / "s")
    identify(tmp_path / "s", report=False)
    rows = read_table(tmp_path / "s" / "stages" / "validation.arrow").to_pylist()
    assert len(rows) == 25 and max(r["error_cm"] for r in rows) <= 1e-9


def test_import_refused_while_the_session_is_locked(tmp_path: Path) -> None:
    from recording_data import locked_elsewhere

    from pipeline.errors import SessionLockedError

    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    (tmp_path / "s").mkdir()
    with locked_elsewhere(tmp_path / "s"), pytest.raises(SessionLockedError):
        import_file(src, "sscanss2", TWO_LINK, tmp_path / "s")
    assert not (tmp_path / "s" / "recording.mcap").exists()


def test_validate_command_against_a_second_file(tmp_path: Path) -> None:
    import json

    from typer.testing import CliRunner

    from pipeline.cli import EXIT_REFUSED, app
    from pipeline.identify import identify

    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES, digits=15))
    other = tmp_path / "other.txt"  # the same arm measured at other readings
    other.write_text(sscanss2_text(TWO_LINK, [[-170, -10, 95], [-100, 5, 130]], digits=15))
    runner = CliRunner()
    args = ["validate", str(tmp_path / "s"), "--against", str(other), "--format", "sscanss2"]
    r = runner.invoke(app, args)
    assert r.exit_code == EXIT_REFUSED and r.stderr.startswith("error: cannot read signature")
    assert len(r.stderr.splitlines()) == 1
    import_file(src, "sscanss2", TWO_LINK, tmp_path / "s")
    identify(tmp_path / "s", report=False)
    before = sorted(p.name for p in (tmp_path / "s").rglob("*"))
    r = runner.invoke(app, [*args, "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["n"] == 6 and out["max_cm"] <= 1e-9 and out["registered_max_cm"] <= 1e-9
    assert sorted(p.name for p in (tmp_path / "s").rglob("*")) == before  # nothing written


def test_table_unwraps_angle_jumps(tmp_path: Path) -> None:
    """A revolute reading that wraps (170, -170 = 190 deg) is one sweep once unwrapped."""
    from import_data import tool_points_mm

    q1 = [110.0, 150.0, -170.0, -130.0, -90.0]  # 110 .. 270 deg with a wrap
    rows = []
    for v in q1:
        rows.append([v, 0.0, *tool_points_mm(TWO_LINK, np.array([[v, 0.0]]))[0]])
    for v in (-60.0, 0.0, 60.0):
        rows.append([0.0, v, *tool_points_mm(TWO_LINK, np.array([[0.0, v]]))[0]])
    src = tmp_path / "wrap.csv"
    src.write_text("j1,j2,x,y,z\n" + "\n".join(",".join(f"{c:.12g}" for c in r) for r in rows))
    mp = tmp_path / "map.toml"
    mp.write_text(
        'length_unit = "mm"\n[[targets]]\nx = "x"\ny = "y"\nz = "z"\n'
        '[[joints]]\ncolumn = "j1"\nunit = "deg"\nunwrap = true\n'
        '[[joints]]\ncolumn = "j2"\nunit = "deg"\n[sweeps]\ncolumn = "infer"\n'
    )
    robot = tmp_path / "wide.toml"  # joint 1 turns 270 deg either way
    robot.write_text(TWO_LINK.read_text().replace("[-180.0, 180.0]", "[-270.0, 270.0]", 1))
    import_file(src, "table", robot, tmp_path / "s", mp)
    plan = _read(tmp_path / "s")["/robot/description"][0]["plan"]
    sweeps = {s["joint"]: s for s in plan["sweeps"]}
    assert sweeps[1]["q_first"] == 110.0 and sweeps[1]["q_last"] == pytest.approx(270.0)
    with pytest.raises(ArmsigError, match=r"wrap.csv: line 4: joint 1 \(link1\) reads 190"):
        import_file(src, "table", TWO_LINK, tmp_path / "s2", mp)  # limits -180 to 180
