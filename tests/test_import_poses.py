"""`pipeline import` of a pose set (issue 26): every row a configuration of sweep `poses`,
several targets per row, σ from columns or stated, decimal commas and other separators,
orientation from Euler angles, a seeded split into validation configurations; bad maps and
cells refused in one line naming the key."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from import_data import POSE_REFLECTORS_MM, UR10, pose_set_map, pose_set_table
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.contract.blocks import row_messages
from pipeline.contract.channels import POINT_BLOCK_CHANNELS
from pipeline.contract.mcap_read import read_mcap
from pipeline.errors import ImportFileError
from pipeline.evaluate.validate import validate_against
from pipeline.identify import identify
from pipeline.importers import import_file
from pipeline.kinematics.chain import forward_kinematics
from pipeline.robots.description import load_description
from pipeline.stages.tables import read_table
from pipeline.units import joints_to_internal


def _messages(session: Path) -> dict[str, list[dict]]:
    """The recording's messages, a pose set's blocks as the per-row messages they stand
    for (issue 45)."""
    path = session / "recording.mcap"
    content = read_mcap(path, POINT_BLOCK_CHANNELS, "re-import")
    return {t: [m for _, m in msgs] for t, msgs in row_messages(path, content.messages).items()}


def _import(tmp: Path, *, map_text: str | None = None, **table: str) -> tuple[Path, np.ndarray]:
    tmp.mkdir(exist_ok=True)
    src, q = pose_set_table(tmp / "poses.csv", **table)  # type: ignore[arg-type]
    mp = tmp / "map.toml"
    keys = {k: v for k, v in table.items() if k in ("sep", "decimal", "unit")}
    mp.write_text(map_text if map_text is not None else pose_set_map(**keys))
    import_file(src, "table", UR10, tmp / "s", mp)
    return tmp / "s", q


@pytest.mark.parametrize(
    ("sep", "decimal", "unit"), [(";", ",", "rad"), (",", ".", "deg"), ("\t", ",", "deg")]
)
def test_pose_set_plan_points_and_readings(tmp_path: Path, sep: str, decimal: str, unit: str):
    session, q = _import(tmp_path, sep=sep, decimal=decimal, unit=unit)
    msgs = _messages(session)
    plan = msgs["/robot/description"][0]["plan"]
    assert plan["poses"] == {"n_points": 40, "targets": ["tmac", "r2"]}
    assert plan["tool_target"] == "tmac" and plan["order"] == ["poses"]
    assert plan["sweeps"] == [] and plan["tool_local_cm"] == [0.0, 0.0, 0.0]
    js = sorted((m["step"], m["q_encoder"]) for m in msgs["/robot/joint_state"])
    assert {m["sweep"] for m in msgs["/robot/joint_state"]} == {"poses"}
    np.testing.assert_allclose([v for _, v in js], q, atol=1e-9)  # file order, deg
    robot = load_description(UR10)
    T = forward_kinematics(robot.design_chain(), joints_to_internal(q, robot.prismatic))
    pts = {(p["step"], p["target"]): p for p in msgs["/points"]}
    for t, local in POSE_REFLECTORS_MM.items():
        want = (T[:, :3, :3] @ (local / 10.0)) + T[:, :3, 3]
        got = np.array([[pts[k, t][f"{a}_cm"] for a in "xyz"] for k in range(40)])
        np.testing.assert_allclose(got, want, atol=1e-9)


@pytest.mark.parametrize(
    ("sigma", "want"),
    [
        ("axes", {"cov_cm2": [[1e-6, 0, 0], [0, 4e-6, 0], [0, 0, 9e-6]]}),
        ("column", {"sigma_cm": 0.001}),
        ("stated", {"sigma_cm": 0.002}),
        ("none", {}),
    ],
)
def test_point_sigma_from_columns_or_stated(tmp_path: Path, sigma: str, want: dict) -> None:
    session, _ = _import(tmp_path, map_text=pose_set_map(sigma=sigma))
    for p in _messages(session)["/points"]:
        got = {k: p[k] for k in ("sigma_cm", "cov_cm2") if k in p}
        assert got.keys() == want.keys()
        for k, v in want.items():
            np.testing.assert_allclose(got[k], v, rtol=1e-12, atol=1e-15)


def test_orientation_of_the_tool_target(tmp_path: Path) -> None:
    session, q = _import(tmp_path)
    robot = load_description(UR10)
    R = forward_kinematics(robot.design_chain(), joints_to_internal(q, robot.prismatic))[:, :3, :3]
    pts = sorted((p["step"], p) for p in _messages(session)["/points"] if p["target"] == "tmac")
    wxyz = np.array([p["orientation_wxyz"] for _, p in pts])
    got = Rotation.from_quat(wxyz[:, [1, 2, 3, 0]]).as_matrix()
    np.testing.assert_allclose(got, R, atol=1e-9)
    assert not any("orientation_wxyz" in p for p in _messages(session)["/points"]
                   if p["target"] == "r2")  # fmt: skip


def test_tool_offset_and_seeded_check_split(tmp_path: Path) -> None:
    extra = "tool_offset = [50.0, 0.0, 100.0]\n\n[check]\nfraction = 0.25\nseed = 7"
    session, _ = _import(tmp_path, map_text=pose_set_map(extra=extra))
    msgs = _messages(session)
    plan = msgs["/robot/description"][0]["plan"]
    assert plan["tool_local_cm"] == [5.0, 0.0, 10.0]
    assert plan["poses"]["n_points"] == 30 and plan["check"] == {"n_points": 10}
    assert plan["order"] == ["poses", "check"]
    check = sorted(m["step"] for m in msgs["/robot/joint_state"] if m["sweep"] == "check")
    assert check == list(range(10))
    rows = [m["q_encoder"] for m in msgs["/robot/joint_state"] if m["sweep"] == "check"]
    session2, _ = _import(tmp_path / "again", map_text=pose_set_map(extra=extra))
    rows2 = [m["q_encoder"] for m in _messages(session2)["/robot/joint_state"]
             if m["sweep"] == "check"]  # fmt: skip
    assert rows == rows2  # the split is the seed's


def test_noiseless_pose_set_identifies_and_validates(tmp_path: Path) -> None:
    extra = "[check]\nfraction = 0.25\nseed = 7"
    session, _ = _import(tmp_path, map_text=pose_set_map(extra=extra))
    identify(session, report=False)
    v = read_table(session / "stages" / "validation.arrow").to_pylist()
    assert {r["role"] for r in v} == {"check", "fit"} and len(v) == 40
    assert max(r["error_cm"] for r in v) <= 1e-6
    other, _ = pose_set_table(tmp_path / "other.csv", n=25, seed=2)
    out = validate_against(session, other, "table", tmp_path / "map.toml")
    assert out["target"] == "tmac" and out["n"] == 25 and out["max_cm"] <= 1e-6
    # Issue 44: a repeated Euler axis (exit 70), a coordinate of 1e308 (an SVD spinning for
    # minutes): one line each, before any linear algebra (a fresh process, killed at 60 s).
    xxy = tmp_path / "xxy.toml"
    xxy.write_text(pose_set_map().replace('convention = "XYZ"', 'convention = "XXY"'))
    lines = other.read_text().splitlines()
    cells = lines[3].split(";")
    cells[8] = "1e308"  # tmac_z, mm
    far = tmp_path / "far.csv"
    far.write_text("\n".join([*lines[:3], ";".join(cells), *lines[4:]]) + "\n")
    for src, mp, words in (
        (other, xxy, "xxy.toml: orientation.convention: must be one of"),
        (far, tmp_path / "map.toml", "far.csv: line 4: target tmac lies 1e+307 cm from"),
    ):
        argv = ["validate", str(session), "--against", str(src), "--format", "table"]
        r = subprocess.run([sys.executable, "-m", "pipeline", *argv, "--map", str(mp)],
                           capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
        assert r.returncode == EXIT_REFUSED and r.stderr.count("\n") == 1, r.stderr
        assert words in r.stderr, r.stderr


#: The map's last top-level keys: a table inserted after them takes none of them.
_TOP = 'sweep = "poses"\ntool_target = "tmac"'


BAD_MAPS = {
    "header not a boolean": (('sweep = "poses"', 'sweep = "poses"\nheader = "false"'),
                             ["map.toml: header: must be boolean", "got 'false'"]),
    "unknown key": (('sweep = "poses"', 'sweep = "poses"\nsigma_mm = 0.05'),
                    ["map.toml: map: must not contain {'sigma_mm'}", "one of the keys"]),
    "sweep not poses": (('sweep = "poses"', 'sweep = "pose"'),
                        ["map.toml: sweep: must be one of ['poses']", "got 'pose'"]),
    "sweeps with poses": ((_TOP, _TOP + '\n[sweeps]\ncolumn = "infer"'),
                          ['map.toml: sweeps: is not read with sweep = "poses"']),
    "σ column and σ per axis": (('sigma_x = "tmac_sx"', 'sigma = "tmac_sx"\nsigma_x = "tmac_sx"'),
                                ["map.toml: targets[1]: has both sigma and sigma_x/y/z"]),
    "σ of one axis only": (('sigma_y = "tmac_sy"\nsigma_z = "tmac_sz"', ""),
                           ["targets[1]: names some but not all sigma_x/y/z columns"]),
    "σ stated and columns": (('sweep = "poses"', 'sweep = "poses"\nsigma = 0.05'),
                             ["map.toml: sigma: is stated and targets[0] has σ columns too"]),
    "σ stated zero": (('sweep = "poses"', 'sweep = "poses"\nsigma = 0'),
                      ["map.toml: sigma: must be bigger than 0"]),
    "repeated Euler axis": (('convention = "XYZ"', 'convention = "XXY"'),
                            ["map.toml: orientation.convention: must be one of", "got 'XXY'"]),
    "σ not finite": (('sweep = "poses"', 'sweep = "poses"\nsigma = nan'),
                     ["map.toml: sigma: is not a finite number"]),
    "unknown tool target": (('tool_target = "tmac"', 'tool_target = "t9"'),
                            ["map.toml: tool_target: is not the id of a [[targets]] table",
                             "expected r2 | tmac"]),
    "check fraction 1": ((_TOP, _TOP + '\n[check]\nfraction = 1.0\nseed = 1'),
                         ["map.toml: check.fraction: must be smaller than 1"]),
    "check seed missing": ((_TOP, _TOP + '\n[check]\nfraction = 0.3'),
                           ["map.toml: check: missing dependency seed for fraction"]),
    "check without poses": ((_TOP, 'tool_target = "tmac"\n[check]\nfraction = 0.3\nseed = 1'),
                            ['map.toml: check: applies to a pose set only']),
    "bad Euler sequence": (('convention = "XYZ"', 'convention = "XYx"'),
                           ["map.toml: orientation.convention: must be one of", "got 'XYx'"]),
    "unwrap in a pose set": (('unit = "rad"', 'unit = "rad"\nunwrap = true'),
                             ["map.toml: joints[0].unwrap: has no sweep to unwrap"]),
    "column number zero": (('x = "tmac_x"', "x = 0"),
                           ["map.toml: targets[1].x: must be valid exactly by one definition",
                            "a 1-based column number"]),
    "held joint beyond the robot": (
        (_TOP, 'tool_target = "tmac"\n[[sweeps.select]]\njoint = 2\nheld = { "13" = 0 }'),
        ["map.toml: sweeps.select[0].held: must not contain {'13'}"]),
}  # fmt: skip

BAD_CELLS = {
    "a '.' with decimal commas": (
        lambda ls: [ls[0], ls[1].replace(",", ".", 1), *ls[2:]],
        ["poses.csv: line 2: column 1 (joint 1) holds a '.' in a file with decimal commas"],
    ),
    "σ negative": (  # a σ of 0 is raised to the floor (issue 42: test_import_layouts.py)
        lambda ls: [
            ls[0],
            ";".join([*ls[1].split(";")[:15], "-0,01", *ls[1].split(";")[16:]]),
            *ls[2:],
        ],  # fmt: skip
        ["poses.csv: line 2: a point's σ is zero or negative"],
    ),
    # A column σ far below any instrument (1e-200, issue 44) is raised to the floor and a
    # missing value drops its row, both said in a warning (issue 42: test_import_layouts.py);
    # a stated σ under 1 nm is refused (test_a_stated_sigma_far_below_any_instrument_is_refused).
    "too few rows for the split": (
        lambda ls: ls[:2],
        ["poses.csv: check.fraction 0.3 of 1 rows leaves 1 poses and 0 validation"],
    ),
}


def _refused(tmp: Path, map_text: str, edit=lambda ls: ls) -> str:  # type: ignore[no-untyped-def]
    src, _ = pose_set_table(tmp / "poses.csv")
    src.write_text("\n".join(edit(src.read_text().splitlines())) + "\n")
    (tmp / "map.toml").write_text(map_text)
    session = tmp / "sessions" / "s"
    args = [str(src), "--format", "table", "--map", str(tmp / "map.toml"), "--robot", str(UR10)]
    r = CliRunner().invoke(app, ["import", *args, str(session)])
    assert r.exit_code == EXIT_REFUSED, (r.exit_code, r.output)
    assert not session.exists() or not any(session.iterdir())
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "try:" in lines[0], r.stderr
    return lines[0]


@pytest.mark.parametrize("case", BAD_MAPS)
def test_bad_map_one_line_naming_the_key(tmp_path: Path, case: str) -> None:
    (old, new), fragments = BAD_MAPS[case]
    text = pose_set_map()
    assert old in text, old
    line = _refused(tmp_path, text.replace(old, new, 1))
    for f in fragments:
        assert f in line, (f, line)


@pytest.mark.parametrize("case", BAD_CELLS)
def test_bad_cell_one_line_naming_the_line(tmp_path: Path, case: str) -> None:
    edit, fragments = BAD_CELLS[case]
    extra = "[check]\nfraction = 0.3\nseed = 1" if "split" in case else ""
    line = _refused(tmp_path, pose_set_map(extra=extra), edit)
    for f in fragments:
        assert f in line, (f, line)


def test_payloads_import_from_a_column_or_stated(tmp_path: Path) -> None:
    """Issue 27: a payload column (kg) or one stated payload becomes joint_state payload_kg;
    two payloads give the fit payload terms (docs/nongeometric.md#payload)."""
    src, _ = pose_set_table(tmp_path / "poses.csv")
    lines = src.read_text().splitlines()
    kg = [0.0 if k % 2 else 10.0 for k in range(len(lines) - 1)]
    rows = [f"{row};{v:g}" for row, v in zip(lines[1:], kg, strict=True)]
    src.write_text("\n".join([lines[0] + ";load", *rows]) + "\n")
    mp = tmp_path / "map.toml"
    mp.write_text('payload_column = "load"\n' + pose_set_map())
    import_file(src, "table", UR10, tmp_path / "col", mp)
    states = sorted((m["step"], m["payload_kg"]) for m in
                    _messages(tmp_path / "col")["/robot/joint_state"])  # fmt: skip
    assert [v for _, v in states] == kg
    identify(tmp_path / "col", report=False)
    joints = read_table(tmp_path / "col" / "stages" / "joints.arrow")
    assert set(joints.column("payload_kg").to_pylist()) == {0.0, 10.0}
    mp.write_text("payload_kg = 5\n" + pose_set_map())
    import_file(src, "table", UR10, tmp_path / "stated", mp)
    assert {m["payload_kg"] for m in _messages(tmp_path / "stated")["/robot/joint_state"]} == {5.0}


def test_a_bad_payload_is_refused_in_one_line(tmp_path: Path) -> None:
    src, _ = pose_set_table(tmp_path / "poses.csv")
    lines = src.read_text().splitlines()
    src.write_text("\n".join([lines[0] + ";load"] + [f"{r};-1" for r in lines[1:]]) + "\n")
    mp = tmp_path / "map.toml"
    mp.write_text('payload_column = "load"\n' + pose_set_map())
    with pytest.raises(ImportFileError, match=r"line 2: payload -1 kg; expected a payload from 0"):
        import_file(src, "table", UR10, tmp_path / "s", mp)
    mp.write_text('payload_column = "load"\npayload_kg = 2\n' + pose_set_map())
    with pytest.raises(ImportFileError, match="payload_kg: is stated and payload_column is given"):
        import_file(src, "table", UR10, tmp_path / "t", mp)


def test_a_byte_order_mark_is_read_and_a_row_wider_than_the_header_refused(tmp_path: Path) -> None:
    """Issue 44: Excel's "CSV UTF-8" (a BOM before the header) was refused with an invisible
    character in the message; a row with a cell too many was read by position, shifted."""
    plain, _ = _import(tmp_path / "plain")
    src = tmp_path / "plain" / "poses.csv"
    bom = tmp_path / "bom"
    bom.mkdir()
    (bom / "poses.csv").write_bytes(b"\xef\xbb\xbf" + src.read_bytes())
    import_file(bom / "poses.csv", "table", UR10, bom / "s", tmp_path / "plain" / "map.toml")
    assert _messages(bom / "s") == _messages(plain)
    lines = src.read_text().splitlines()
    lines[3] = "0;" + lines[3]  # a cell too many at the front: every column shifted
    lines[5] += ";;"  # empty cells after the last column: a trailing delimiter, harmless
    wide = tmp_path / "wide.csv"
    wide.write_text("\n".join(lines) + "\n")
    with pytest.raises(ImportFileError, match=r"wide.csv: line 4: \d+ cells for the header's \d+"):
        import_file(wide, "table", UR10, tmp_path / "w", tmp_path / "plain" / "map.toml")
    assert not (tmp_path / "w").exists()
    lines[3] = lines[3][2:]
    wide.write_text("\n".join(lines) + "\n")
    import_file(wide, "table", UR10, tmp_path / "w", tmp_path / "plain" / "map.toml")


def test_a_stated_sigma_far_below_any_instrument_is_refused(tmp_path: Path) -> None:
    """Issue 44: a map's ``sigma = 1e-200`` (the schema's > 0) was imported, then
    ``identify`` died in a LinAlgError (exit 70)."""
    text = pose_set_map(sigma="stated").replace("sigma = 0.02", "sigma = 1e-200")
    line = _refused(tmp_path, text)
    assert "poses.csv: line 2: a point's σ is under 1 nm" in line and "got 1e-201 cm" in line
