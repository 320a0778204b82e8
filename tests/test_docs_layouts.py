"""docs/import.md, "Layouts labs write" (issue 42): every example file and map of the
section imports as the text says, and every quoted warning and error is the command's
own line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from import_data import UR10
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app

DOC = Path(__file__).resolve().parent.parent / "docs" / "import.md"
SECTION = DOC.read_text().split("## Layouts labs write (issue 42)")[1].split("\n## ")[0]


def _blocks() -> dict[str, str]:
    """Each "`name`:" block of the section: its text."""
    found = re.findall(r"`([\w.]+)`:\n\n```\w*\n(.*?)```", SECTION, flags=re.S)
    return dict(found)


def _quoted(start: str) -> str:
    """The section's quoted line that starts with ``start`` (a code block's line, or the
    text's, joined over its line breaks)."""
    text = re.sub(r"\s*\n\s*", " ", SECTION)
    m = re.search(re.escape(start) + r"[^`]*", text)
    assert m, start
    return m.group(0).strip()


def _run(tmp: Path, files: list[str], map_name: str, *extra: str, fmt: str = "table"):  # type: ignore[no-untyped-def]
    blocks = _blocks()
    for name in (*files, map_name):  # a file the test wrote itself is kept
        if name in blocks and not (tmp / name).exists():
            (tmp / name).write_text(blocks[name])
    args = [*(str(tmp / f) for f in files), str(tmp / "s"), "--format", fmt, "--robot",
            str(UR10), "--map", str(tmp / map_name), *extra]  # fmt: skip
    return CliRunner().invoke(app, ["import", *args])


def test_several_files_and_globs(tmp_path: Path) -> None:
    blocks = _blocks()
    lines = blocks["poses.csv"].splitlines()
    for k, part in enumerate((lines[1:4], lines[4:7], lines[7:]), 1):
        (tmp_path / f"region_{k}.csv").write_text("\n".join([lines[0], *part]) + "\n")
    (tmp_path / "poses.toml").write_text(blocks["poses.toml"])
    args = [str(tmp_path / "region_*.csv"), str(tmp_path / "s"), "--format", "table",
            "--robot", str(UR10), "--map", str(tmp_path / "poses.toml")]  # fmt: skip
    r = CliRunner().invoke(app, ["import", *args])
    assert r.exit_code == 0 and "9 configurations (9 poses" in r.output, r.output


def test_joined_by_row_and_its_mismatch(tmp_path: Path) -> None:
    blocks = _blocks()
    (tmp_path / "r2.csv").write_text(blocks["tmac.csv"])
    r = _run(tmp_path, ["joints.csv", "tmac.csv", "r2.csv"], "join.toml")
    assert r.exit_code == 0, r.output
    short = "\n".join(blocks["tmac.csv"].splitlines()[:-1]) + "\n"
    (tmp_path / "r2.csv").write_text(short)
    r = _run(tmp_path, ["joints.csv", "tmac.csv", "r2.csv"], "join.toml", "--force")
    assert r.exit_code == EXIT_REFUSED
    assert r.stderr.strip() == _quoted("error: r2.csv: 8 rows"), r.stderr


def test_stacked_rows(tmp_path: Path) -> None:
    blocks = _blocks()
    (tmp_path / "joints.csv").write_text("\n".join(blocks["joints.csv"].splitlines()[:4]) + "\n")
    r = _run(tmp_path, ["joints.csv", "points.csv"], "stacked.toml")
    assert r.exit_code == 0 and "3 configurations (3 poses" in r.output, r.output
    (tmp_path / "points.csv").write_text(blocks["points.csv"] + "1.0,2.0,3.0\n")
    args = [str(tmp_path / f) for f in ("joints.csv", "points.csv")]
    mp = str(tmp_path / "stacked.toml")
    r = CliRunner().invoke(app, ["import", *args, str(tmp_path / "t"), "--format", "table",
                                 "--robot", str(UR10), "--map", mp])  # fmt: skip
    assert r.exit_code == EXIT_REFUSED
    assert r.stderr.startswith(_quoted("error: points.csv: 10 rows").removesuffix("; ...")), (
        r.stderr
    )
    text = blocks["stacked.toml"].replace("points_per_pose = 3", 'pose_column = "pose"')
    (tmp_path / "by_pose.toml").write_text(re.sub(r'file = "[\w.]+", ', "", text))
    (tmp_path / "by_pose.csv").write_text(blocks["by_pose.csv"])
    r = CliRunner().invoke(app, ["import", str(tmp_path / "by_pose.csv"), str(tmp_path / "u"),
                                 "--format", "table", "--robot", str(UR10), "--map",
                                 str(tmp_path / "by_pose.toml")])  # fmt: skip
    assert r.exit_code == 0 and "3 configurations (3 poses" in r.output, r.output


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_mat_file_as_the_matlab_lines_write_it(tmp_path: Path, version: str) -> None:
    from layout_data import write_v73

    rows = [[float(v) for v in ln.split(",")] for ln in _blocks()["poses.csv"].splitlines()[1:]]
    a = np.array(rows)
    arrays = {"Q": a[:, :6], "P_tmac": a[:, 6:9], "P_r2": a[:, 9:12]}
    path = tmp_path / "poses.mat"
    if version == "v5":
        from scipy.io import savemat

        savemat(path, arrays)
    else:
        write_v73(path, arrays)
    (tmp_path / "mat.toml").write_text(_blocks()["mat.toml"])
    r = _run(tmp_path, ["poses.mat"], "mat.toml", fmt="mat")
    assert r.exit_code == 0 and "9 configurations (9 poses" in r.output, r.output
    (tmp_path / "mat.toml").write_text(_blocks()["mat.toml"].replace('"P_r2:', '"P_r3:'))
    r = _run(tmp_path, ["poses.mat"], "mat.toml", "--force", fmt="mat")
    assert r.exit_code == EXIT_REFUSED
    assert r.stderr.strip() == _quoted("error: poses.mat: no variable 'P_r3'").replace(
        "P_r2, P_r3, Q", "P_r3, P_tmac, Q"
    ), r.stderr


def test_rows_without_a_measurement(tmp_path: Path) -> None:
    r2 = ',\n           { id = "r2", x = "x2", y = "y2", z = "z2" }'
    text = _blocks()["poses.toml"]
    assert r2 in text
    (tmp_path / "lost.toml").write_text(text.replace(r2, ""))
    r = _run(tmp_path, ["lost_beam.csv"], "lost.toml")
    assert r.exit_code == 0, r.output
    want = _quoted("warning: lost_beam.csv: 2 of 9 rows dropped")
    assert r.stderr.strip().replace(str(tmp_path) + "/", "") == want, r.stderr
    r = _run(tmp_path, ["lost_beam.csv"], "lost.toml", "--force", "--strict")
    assert r.exit_code == EXIT_REFUSED and "--strict" in r.stderr


def test_fixed_targets_on_the_base(tmp_path: Path) -> None:
    r = _run(tmp_path, ["with_base.csv"], "base.toml")
    assert r.exit_code == 0, r.output
    assert r.stderr.strip() == _quoted("warning: with_base.csv: fixed targets b1, b2, b3"), r.stderr


def test_polars_query_of_the_section(tmp_path: Path) -> None:
    """The section's polars lines read a stage table and name the rows' sources."""
    import polars as pl
    from layout_data import one_file, pose_set

    from pipeline.identify import identify

    text = one_file(pose_set(), tmp_path)[1]  # 42 poses: the section's 9 are too few to fit
    (tmp_path / "poses.toml").write_text(text + "\n[check]\nrows = [[7, 9]]\n")
    import_args = [str(tmp_path / "poses.csv"), str(tmp_path / "s"), "--format", "table",
                   "--robot", str(UR10), "--map", str(tmp_path / "poses.toml")]  # fmt: skip
    assert CliRunner().invoke(app, ["import", *import_args]).exit_code == 0
    identify(tmp_path / "s", report=False)
    v = pl.read_ipc(tmp_path / "s" / "stages" / "validation.arrow")
    top = v.filter(pl.col("role") == "check").sort("error_cm", descending=True).select(
        "source_file", "source_line", "error_cm").head(5)  # fmt: skip
    assert sorted(top["source_line"].to_list()) == [8, 9, 10]
    assert set(top["source_file"].to_list()) == {"poses.csv"}
