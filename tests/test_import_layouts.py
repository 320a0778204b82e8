"""Issue 42: a data set as labs write it imports as it is. One simulated pose set written
as seven files, per-quantity files joined by row, stacked rows, a pose column, MATLAB v5
and v7.3 imports to the recording of the one-file session (every value, bit for bit;
only each row's source file and line differ), and identifies to the same signature. Each
mismatch is one line naming the file."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from import_data import UR10
from layout_data import (
    mat_file,
    one_file,
    per_quantity,
    pose_column,
    pose_set,
    seven_files,
    stacked,
)
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app
from pipeline.contract.blocks import row_messages
from pipeline.contract.channels import POINT_BLOCK_CHANNELS
from pipeline.contract.mcap_read import McapContent, read_mcap
from pipeline.importers import import_file

LAYOUTS = {
    "seven files": seven_files,
    "per-quantity files": per_quantity,
    "stacked rows": stacked,
    "pose column": pose_column,
    "mat v5": lambda ps, d: mat_file(ps, d, "v5"),
    "mat v7.3": lambda ps, d: mat_file(ps, d, "v73"),
}
SOURCE = ("source_file", "source_line")


def imported(folder: Path, layout, ps=None) -> Path:  # type: ignore[no-untyped-def]
    folder.mkdir(parents=True, exist_ok=True)
    paths, text = layout(ps or pose_set(), folder)
    mp = folder / "map.toml"
    mp.write_text(text)
    fmt = "mat" if paths[0].suffix == ".mat" else "table"
    import_file([str(p) for p in paths], fmt, UR10, folder / "s", mp)
    return folder / "s"


def _read(session: Path) -> McapContent:
    """The recording, a pose set's blocks as the per-row messages they stand for (issue
    45: the messages as written before blocks)."""
    path = session / "recording.mcap"
    content = read_mcap(path, POINT_BLOCK_CHANNELS, "test")
    return replace(content, messages=row_messages(path, content.messages))


def messages(session: Path, keep_source: bool = False) -> dict[str, list[dict]]:
    """The recording's messages; ``keep_source``: each joint state's source_file as the
    contract gives it (its own, else armsig.source's one file), else none."""
    content = _read(session)
    out = {t: [m for _, m in msgs] for t, msgs in content.messages.items()}
    out["/rig/description"] = []  # names the files
    one_file = content.metadata["armsig.source"]["file"]
    for m in out["/robot/joint_state"]:
        if keep_source:
            m.setdefault("source_file", one_file)
        else:
            for k in SOURCE:
                m.pop(k, None)
    return out


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return imported(tmp_path_factory.mktemp("one"), one_file)


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_layout_imports_to_the_one_file_recording(tmp_path: Path, reference: Path, name: str):
    session = imported(tmp_path, LAYOUTS[name])
    assert messages(session) == messages(reference)


def test_rows_keep_their_source_file_and_line(tmp_path: Path) -> None:
    session = imported(tmp_path, seven_files)
    js = messages(session, keep_source=True)["/robot/joint_state"]
    first = [m for m in js if m["step"] == 0][0]
    assert (first["source_file"], first["source_line"]) == ("region_1.csv", 2)
    last = max(js, key=lambda m: m["step"])
    assert last["source_file"] == "region_7.csv" and last["source_line"] == 7  # 6 rows + header
    raw = _read(session).messages
    assert all("source_file" in m for _, m in raw["/robot/joint_state"])  # several files
    mat = imported(tmp_path / "mat", LAYOUTS["mat v7.3"])
    content = _read(mat)
    assert all("source_file" not in m for _, m in content.messages["/robot/joint_state"])
    js = messages(mat, keep_source=True)["/robot/joint_state"]  # one file: armsig.source's
    assert {m["source_file"] for m in js} == {"poses_v73.mat"}
    assert sorted(m["source_line"] for m in js) == list(range(1, 43))


def test_globs_in_order_and_same_signature(tmp_path: Path, reference: Path) -> None:
    """Seven files given as a glob identify to the one-file session's signature, bit for
    bit (the document but its provenance: the recordings differ in source names only)."""
    from pipeline.identify import identify
    from pipeline.stages.tables import read_table

    paths, text = seven_files(pose_set(), tmp_path)
    (tmp_path / "map.toml").write_text(text)
    import_file(
        str(tmp_path / "region_*.csv"), "table", UR10, tmp_path / "s", tmp_path / "map.toml"
    )
    docs = []
    for s in (reference, tmp_path / "s"):
        identify(s, report=False)
        doc = json.loads((s / "signature.json").read_text())
        docs.append({k: v for k, v in doc.items() if k not in ("provenance", "sha256")})
    assert docs[0] == docs[1]
    v = read_table(tmp_path / "s" / "stages" / "validation.arrow").to_pylist()
    assert {r["source_file"] for r in v} == {f"region_{k}.csv" for k in range(1, 8)}
    j = read_table(tmp_path / "s" / "stages" / "joints.arrow").to_pylist()
    assert all(r["source_line"] >= 2 for r in j)
    for name in ("positions", "holdout"):  # every table with rows names them
        rows = read_table(tmp_path / "s" / "stages" / f"{name}.arrow").to_pylist()
        assert rows and {r["source_file"] for r in rows} == {f"region_{k}.csv" for k in range(1, 8)}
        assert all(r["source_line"] >= 2 for r in rows), name


def _signature(session: Path) -> dict:  # type: ignore[type-arg]
    """The identified signature document but its provenance (recording and table hashes:
    the recordings differ in their rows' source names only) and self-digest."""
    from pipeline.identify import identify

    identify(session, report=False)
    doc = json.loads((session / "signature.json").read_text())
    return {k: v for k, v in doc.items() if k not in ("provenance", "sha256")}


def test_every_layout_identifies_to_the_one_file_signature(tmp_path: Path, reference: Path) -> None:
    """Issue 42's acceptance: each layout's session (and the file with 10 % of its rows
    NaN, against the one file of the other rows) identifies to the same signature, bit for
    bit."""
    from layout_data import PoseSet

    want = _signature(reference)
    for name, layout in LAYOUTS.items():
        assert _signature(imported(tmp_path / name.replace(" ", "_"), layout)) == want, name
    ps = pose_set(n=50)
    bad = [3, 11, 19, 27, 45]
    keep = np.setdiff1d(np.arange(50), bad)
    kept = PoseSet(ps.q_rad[keep], {t: p[keep] for t, p in ps.points_mm.items()})
    nan = _with_nan(ps, bad, [2, 6, 6, 8, 2])
    assert _signature(imported(tmp_path / "nan", one_file, nan)) == _signature(
        imported(tmp_path / "kept", one_file, kept)
    )


def _refused(tmp: Path, paths: list[Path], text: str, fmt: str = "table") -> str:
    """The command's one line (exit 2, nothing written)."""
    mp = tmp / "map.toml"
    mp.write_text(text)
    args = [*map(str, paths), str(tmp / "s"), "--format", fmt, "--robot", str(UR10), "--map",
            str(mp)]  # fmt: skip
    r = CliRunner().invoke(app, ["import", *args])
    assert r.exit_code == EXIT_REFUSED, (r.exit_code, r.output)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "try:" in lines[0], r.stderr
    assert not (tmp / "s" / "recording.mcap").exists()
    return lines[0]


def test_row_counts_differ_one_line_naming_the_file(tmp_path: Path) -> None:
    paths, text = per_quantity(pose_set(), tmp_path)
    r2 = tmp_path / "r2.csv"
    r2.write_text("\n".join(r2.read_text().splitlines()[:-1]) + "\n")
    line = _refused(tmp_path, paths, text)
    assert line.startswith("error: r2.csv: 41 rows, but joints.csv has 42"), line


def test_stacked_rows_not_a_multiple_one_line(tmp_path: Path) -> None:
    paths, text = stacked(pose_set(), tmp_path)
    pts = tmp_path / "points.csv"
    pts.write_text(pts.read_text() + "1.0,2.0,3.0\n")
    line = _refused(tmp_path, paths, text)
    assert line.startswith("error: points.csv: 85 rows, not a multiple of points_per_pose = 2"), (
        line
    )


def test_mat_variable_absent_one_line_naming_the_file(tmp_path: Path) -> None:
    paths, text = mat_file(pose_set(), tmp_path, "v5")
    line = _refused(tmp_path, paths, text.replace('"P_r2:', '"P_r3:'), "mat")
    assert line.startswith("error: poses_v5.mat: no variable 'P_r3'"), line
    paths, text = mat_file(pose_set(), tmp_path, "v73")
    line = _refused(tmp_path, paths, text.replace('"Q:', '"Joints:'), "mat")
    assert line.startswith("error: poses_v73.mat: no variable 'Joints'"), line


def test_a_given_file_the_map_does_not_read_is_refused(tmp_path: Path) -> None:
    paths, text = per_quantity(pose_set(), tmp_path)
    extra = tmp_path / "notes.csv"
    extra.write_text("a\n1\n")
    line = _refused(tmp_path, [*paths, extra], text)
    assert line.startswith("error: notes.csv: the map reads no column of this file"), line


def test_validate_against_several_files_uses_them_all(tmp_path: Path, reference: Path) -> None:
    """`validate --against A --against B` (issue 44: it used B alone, exit 0)."""
    from pipeline.identify import identify

    identify(reference, report=False)
    paths, text = seven_files(pose_set(n=21, seed=9), tmp_path)
    mp = tmp_path / "map.toml"
    mp.write_text(text)
    args = ["validate", str(reference), "--format", "table", "--map", str(mp), "--json"]
    one = CliRunner().invoke(app, [*args, "--against", str(paths[0])])
    two = CliRunner().invoke(app, [*args, "--against", str(paths[0]), "--against", str(paths[1])])
    every = CliRunner().invoke(app, [*args, "--against", str(tmp_path / "region_*.csv")])
    assert one.exit_code == two.exit_code == every.exit_code == 0, two.output
    n = [json.loads(r.stdout)["n"] for r in (one, two, every)]
    assert n == [3, 6, 21]
    assert json.loads(two.stdout)["files"] == ["region_1.csv", "region_2.csv"]
    bad = CliRunner().invoke(app, [*args, "--against", str(tmp_path / "nothing_*.csv")])
    assert bad.exit_code == EXIT_REFUSED and "no file matches" in bad.output


def test_import_cli_takes_several_files(tmp_path: Path, reference: Path) -> None:
    paths, text = per_quantity(pose_set(), tmp_path)
    mp = tmp_path / "map.toml"
    mp.write_text(text)
    out = CliRunner().invoke(app, ["import", *map(str, paths), str(tmp_path / "s"), "--format",
                                   "table", "--robot", str(UR10), "--map", str(mp)])  # fmt: skip
    assert out.exit_code == 0, out.output
    assert messages(tmp_path / "s") == messages(reference)
    assert "42 configurations (42 poses" in out.output


def _with_nan(ps, rows: list[int], cols: list[int]):  # type: ignore[no-untyped-def]
    """The pose set with one value of each of ``rows`` NaN (column ``cols[k]`` of the
    joints then the tool reflector's x, y, z)."""
    from layout_data import PoseSet

    q, tm = ps.q_rad.copy(), ps.points_mm["tmac"].copy()
    for r, c in zip(rows, cols, strict=True):
        if c < 6:
            q[r, c] = np.nan
        else:
            tm[r, c - 6] = np.nan
    return PoseSet(q, {**ps.points_mm, "tmac": tm})


def test_rows_with_nan_dropped_counted_and_said(tmp_path: Path) -> None:
    """10 % of the rows with a NaN import as the one-file session of the other rows; the
    drop is one warning line counting per column; --strict refuses in one line."""
    from layout_data import PoseSet

    ps = pose_set(n=50)
    bad = [3, 11, 19, 27, 45]
    nan = _with_nan(ps, bad, [2, 6, 6, 8, 2])
    keep = np.setdiff1d(np.arange(50), bad)
    kept = PoseSet(ps.q_rad[keep], {t: p[keep] for t, p in ps.points_mm.items()})
    ref = imported(tmp_path / "ref", one_file, kept)
    paths, text = one_file(nan, tmp_path)
    mp = tmp_path / "map.toml"
    mp.write_text(text)
    args = [str(paths[0]), str(tmp_path / "s"), "--format", "table", "--robot", str(UR10),
            "--map", str(mp)]  # fmt: skip
    r = CliRunner().invoke(app, ["import", *args])
    assert r.exit_code == 0, r.output
    warnings = [ln for ln in r.stderr.splitlines() if ln.startswith("warning:")]
    assert warnings == [
        "warning: poses.csv: 5 of 50 rows dropped, a measured value missing or not finite (by "
        "column: j3 2, tmac_x 2, tmac_z 1): poses.csv: line 5, poses.csv: line 13, poses.csv: "
        "line 21, poses.csv: line 29, poses.csv: line 47"
    ], r.stderr
    assert messages(tmp_path / "s") == messages(ref)
    lines = [m["source_line"] for m in messages(tmp_path / "s", True)["/robot/joint_state"]]
    assert sorted(lines) == [k + 2 for k in keep]
    strict = CliRunner().invoke(app, ["import", *args, "--force", "--strict"])
    assert strict.exit_code == EXIT_REFUSED
    assert strict.stderr.startswith(
        "error: poses.csv: line 5: a measured value is missing or not a finite number (5 such "
        "rows; by column: j3 2, tmac_x 2, tmac_z 1)"
    ), strict.stderr


def test_sigma_columns_below_the_floor_raised_to_it(tmp_path: Path) -> None:
    """A tracker's σ rounded to 0.000 mm is raised to the floor (default 0.001 mm, or the
    map's sigma_floor) and said, not refused."""
    ps = pose_set(n=12)
    paths, text = one_file(ps, tmp_path)
    src = paths[0]
    lines = src.read_text().splitlines()
    sig = ["0.0" if k == 3 else "0.02" for k in range(12)]
    src.write_text(
        "\n".join([lines[0] + ",s", *(f"{ln},{s}" for ln, s in zip(lines[1:], sig, strict=True))])
        + "\n"
    )
    text = text.replace("sigma = 0.01\n", "")
    for t in ("tmac", "r2"):
        text = text.replace(f'z = "{t}_z"\n', f'z = "{t}_z"\nsigma = "s"\n')
    for extra, want in (("", 0.0001), ("sigma_floor = 0.005\n", 0.0005)):
        mp = tmp_path / "map.toml"
        mp.write_text(extra + text)
        out = import_file(str(src), "table", UR10, tmp_path / "s", mp, force=True)
        assert out.rows.notes == (
            f"poses.csv: the σ of 2 point(s) below the floor {want * 10:g} mm, raised to it "
            "(map: sigma_floor)",
        )
        pts = [m for m in messages(tmp_path / "s")["/points"] if m["target"] == "tmac"]
        assert sorted({m["sigma_cm"] for m in pts}) == [want, 0.002]


def _held(session: Path) -> list[tuple[str, int]]:
    js = messages(session, keep_source=True)["/robot/joint_state"]
    return sorted((m["source_file"], m["source_line"]) for m in js if m["sweep"] == "check")


@pytest.mark.parametrize(
    ("check", "want"),
    [
        ('files = ["region_7.csv"]', [("region_7.csv", k) for k in range(2, 8)]),
        ("rows = [[1, 2], [42, 42]]", [("region_1.csv", 2), ("region_1.csv", 3),
                                       ("region_7.csv", 7)]),
    ],
)  # fmt: skip
def test_held_out_rows_by_name(tmp_path: Path, check: str, want: list) -> None:  # type: ignore[type-arg]
    paths, text = seven_files(pose_set(), tmp_path)
    (tmp_path / "map.toml").write_text(text + f"\n[check]\n{check}\n")
    import_file([str(p) for p in paths], "table", UR10, tmp_path / "s", tmp_path / "map.toml")
    assert _held(tmp_path / "s") == want


def test_held_out_rows_by_column_and_listed_in_the_report(tmp_path: Path) -> None:
    from pipeline.identify import identify
    from pipeline.report.validation import validation_section, validation_table

    paths, text = one_file(pose_set(), tmp_path)
    src = paths[0]
    lines = src.read_text().splitlines()
    held = ["true" if k in (4, 5, 6, 30) else "false" for k in range(42)]
    body = [f"{ln},{h}" for ln, h in zip(lines[1:], held, strict=True)]
    src.write_text("\n".join([lines[0] + ",held", *body]) + "\n")
    (tmp_path / "map.toml").write_text(text + '\n[check]\ncolumn = "held"\n')
    import_file(str(src), "table", UR10, tmp_path / "s", tmp_path / "map.toml")
    assert _held(tmp_path / "s") == [("poses.csv", k) for k in (6, 7, 8, 32)]
    identify(tmp_path / "s", report=False)
    section = validation_section(validation_table(tmp_path / "s" / "stages" / "validation.arrow"))
    assert "Held out (4 rows, by source file and line): poses.csv lines 6-8, 32." in section
    (tmp_path / "map.toml").write_text(text + '\n[check]\ncolumn = "j1"\n')
    args = [str(src), str(tmp_path / "t"), "--format", "table", "--robot", str(UR10)]
    r = CliRunner().invoke(app, ["import", *args, "--map", str(tmp_path / "map.toml")])
    assert r.exit_code == EXIT_REFUSED and "check column holds" in r.stderr, r.stderr


def test_held_out_rows_beyond_the_data_refused(tmp_path: Path) -> None:
    paths, text = seven_files(pose_set(), tmp_path)
    line = _refused(tmp_path, paths, text + "\n[check]\nrows = [[40, 43]]\n")
    assert line.startswith("error: map.toml: check.rows [40, 43] goes beyond the 42 data rows")
    line = _refused(tmp_path, paths, text + '\n[check]\nfiles = ["region_9.csv"]\n')
    assert line.startswith("error: map.toml: check.files names 'region_9.csv', none of the given")


def _audit_cm(session: Path) -> float:
    """The signature's largest tool-point error over 1,000 random configurations against
    the simulated truth (the design model's tmac reflector), the base registered."""
    from layout_data import REFLECTORS_MM

    from pipeline.evaluation.validation import model_points
    from pipeline.kinematics.alignment import register_rigid
    from pipeline.kinematics.chain import forward_kinematics
    from pipeline.robots.description import load_description
    from pipeline.signature.session import load_session_signature
    from pipeline.units import joints_to_internal

    sig = load_session_signature(session / "signature.json")
    q = np.random.default_rng(11).uniform(-170.0, 170.0, (1000, 6))
    model = model_points(sig.chain, q, sig.prismatic, sig.nongeometric)
    robot = load_description(UR10)
    T = forward_kinematics(robot.design_chain(), joints_to_internal(q, robot.prismatic))
    truth = T[:, :3, :3] @ (REFLECTORS_MM["tmac"] / 10.0) + T[:, :3, 3]
    X = register_rigid(model, truth)
    assert X is not None
    return float(np.linalg.norm(model @ X[:3, :3].T + X[:3, 3] - truth, axis=1).max())


def test_fixed_base_reflectors_correct_the_drift(tmp_path: Path) -> None:
    """Three base reflectors with 0.05 mm of tracker drift (read at 0.005 mm, half the arm
    points' noise), each pose registered by the 5 poses around it: the signature audits
    within 1.1x of the driftless session's (uncorrected 2.4x); the drift is recorded per
    pose (joints table) and said in one line. docs/import.md has the other settings."""
    from layout_data import drifting, fixed_map, one_file_all

    from pipeline.identify import identify
    from pipeline.stages.tables import read_table

    ps = pose_set(n=60)
    clean = imported(tmp_path / "clean", one_file, ps)
    drift = drifting(ps, 0.05, noise_mm=0.005)
    src = one_file_all(drift, tmp_path)
    text = one_file(ps, tmp_path / "clean")[1]
    (tmp_path / "fixed.toml").write_text("fixed_block = 5\n" + fixed_map(text))
    (tmp_path / "plain.toml").write_text(text)
    out = import_file(str(src), "table", UR10, tmp_path / "fixed", tmp_path / "fixed.toml")
    import_file(str(src), "table", UR10, tmp_path / "plain", tmp_path / "plain.toml")
    (note,) = out.rows.notes  # the drift seen (F test, tests/test_import_fixed.py): applied
    assert note.startswith(
        "poses.csv: fixed targets b1, b2, b3: drift beyond their noise, corrected (F = "
    ) and (
        "; registered 60 poses by their own readings (windows of 5 poses), 0 by an earlier "
        "one, 0 uncorrected; drift median" in note
    ), note
    audits = {}
    for name in ("clean", "fixed", "plain"):
        identify(tmp_path / name if name != "clean" else clean, report=False)
        audits[name] = _audit_cm(tmp_path / name if name != "clean" else clean)
    print("audit (cm):", audits)
    assert audits["fixed"] <= 1.1 * audits["clean"], audits
    assert audits["plain"] > 2.0 * audits["clean"], audits  # the drift the correction removed
    joints = read_table(tmp_path / "fixed" / "stages" / "joints.arrow")
    j = joints.to_pylist()
    drift_cm = [r["tracker_drift_cm"] for r in j if r["joint"] == 1]
    assert len(drift_cm) == 60 and 0.0 < np.median(drift_cm) < 0.01 and max(drift_cm) < 0.02
    from pipeline.report.validation import validation_section, validation_table

    v = validation_table(tmp_path / "fixed" / "stages" / "validation.arrow")
    text = validation_section(v, joints)
    want = f"median {np.median(drift_cm):.3g} cm, max {max(drift_cm):.3g} cm before the correction"
    assert "Tracker drift by the fixed targets (60 configurations" in text and want in text


def test_a_fixed_target_that_moves_is_one_line(tmp_path: Path) -> None:
    from layout_data import drifting, fixed_map, one_file_all

    ps = pose_set(n=20)
    drift = drifting(ps, 0.05)
    drift.points_mm["b2"][12:] += [100.0, 0.0, 0.0]  # knocked 10 cm at the 13th pose
    text = fixed_map(one_file(ps, tmp_path)[1])
    src = one_file_all(drift, tmp_path)  # the same name: the arm-only file replaced
    line = _refused(tmp_path, [src], text)
    assert line.startswith("error: poses.csv: line 14: fixed target b"), line
    assert "cm from where the other fixed targets put it (it moved)" in line


def test_poses_without_three_fixed_readings_counted(tmp_path: Path) -> None:
    """A pose where a base reflector was not read takes the last registration before it;
    one before any is used uncorrected; both are counted, and no row is dropped."""
    from layout_data import drifting, fixed_map, one_file_all

    ps = pose_set(n=20)
    drift = drifting(ps, 0.05)
    drift.points_mm["b3"][[0, 7, 8]] = np.nan
    mp = tmp_path / "map.toml"
    mp.write_text(fixed_map(one_file(ps, tmp_path)[1]))
    src = one_file_all(drift, tmp_path)  # the same name: the arm-only file replaced
    out = import_file(str(src), "table", UR10, tmp_path / "s", mp)
    assert len(out.rows.where) == 20 and (
        "registered 17 poses by their own readings (each pose), 2 by an earlier one, 1 "
        "uncorrected" in out.rows.notes[0]
    ), out.rows.notes


@pytest.mark.parametrize("fmt", ["sscanss2", "table"])
def test_joint_sweeps_in_two_files(tmp_path: Path, fmt: str) -> None:
    """A sweep file split after joint 1's sweep (SScanSS-2 text, a table whose sweeps are
    inferred) imports to the one file's recording values."""
    from import_data import TWO_LINK, TWO_LINK_MAP, TWO_LINK_VALUES, sscanss2_text, two_link_table

    one = tmp_path / "one.txt"
    if fmt == "sscanss2":
        one.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
        head, cut = [], len(TWO_LINK_VALUES[0])
    else:
        two_link_table(one)
        head, cut = one.read_text().splitlines()[:2], len(TWO_LINK_VALUES[0])
    lines = one.read_text().splitlines()[len(head) :]
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("\n".join([*head, *lines[:cut]]) + "\n")
    b.write_text("\n".join([*head, *lines[cut:]]) + "\n")
    mp = None
    if fmt == "table":
        mp = tmp_path / "map.toml"
        mp.write_text(TWO_LINK_MAP)
    import_file(str(one), fmt, TWO_LINK, tmp_path / "s1", mp)
    import_file([str(a), str(b)], fmt, TWO_LINK, tmp_path / "s2", mp)
    assert messages(tmp_path / "s2") == messages(tmp_path / "s1")
    files = {m["source_file"] for m in messages(tmp_path / "s2", True)["/robot/joint_state"]}
    assert files == {"a.txt", "b.txt"}


def test_skip_lines_with_several_files_refused(tmp_path: Path) -> None:
    """Line numbers name no one file of several: refused, not applied to every file."""
    paths, text = seven_files(pose_set(), tmp_path)
    line = _refused(tmp_path, paths, "skip_lines = [3]\n" + text)
    assert line.startswith("error: map.toml: skip_lines with 7 files: its line numbers name"), line
