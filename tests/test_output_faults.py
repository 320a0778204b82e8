"""Issue 32's leftovers: what used to be exit 70, a misleading line or no word at all.

An output onto an immutable file (``chattr +i``) or a name too long, a stage file that
cannot be replaced, a dangling symlink as the session folder, ``validate`` dropping rows
with NaN, ``show`` printing an edited stage table: each is one line that names the path
and the cause (or a warning), never an internal error."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from fuzz_import import edit_arrow_value
from import_data import TWO_LINK, TWO_LINK_VALUES, sscanss2_text
from typer.testing import CliRunner, Result

from pipeline.cli import EXIT_REFUSED, app
from pipeline.stages.runner import stage_path


def _one_line(r: Result, *words: str) -> None:
    assert r.exit_code == EXIT_REFUSED, (r.exit_code, r.output)
    lines = r.stderr.splitlines()  # identify's progress line may come first
    assert lines[-1].startswith("error: ") and r.stderr.count("error") == 1, r.stderr
    assert "Traceback" not in r.output
    for w in words:
        assert w in r.stderr, (w, r.stderr)


@pytest.fixture
def immutable() -> Iterator[list[Path]]:
    """``chattr +i`` on the paths a test appends (skipped where chattr cannot), undone after."""
    done: list[Path] = []

    def on(path: Path) -> None:
        r = subprocess.run(["chattr", "+i", str(path)], capture_output=True)
        if r.returncode:
            pytest.skip(f"chattr +i needs root and a file system that has it: {r.stderr!r}")
        done.append(path)

    yield on  # type: ignore[misc]
    for p in done:
        subprocess.run(["chattr", "-i", str(p)], capture_output=True)


def test_export_onto_an_immutable_file_is_one_line(identified_session, tmp_path, immutable):
    d = shutil.copytree(identified_session, tmp_path / "s")
    out = tmp_path / "robot.urdf"
    out.write_text("the user's\n")
    immutable(out)
    r = CliRunner().invoke(
        app, ["export", str(d), "--format", "urdf", "--out", str(out), "--force"]
    )
    _one_line(r, f"{out}: Operation not permitted")  # was exit 70 (PermissionError)
    assert out.read_text() == "the user's\n"


def test_identify_onto_an_immutable_stage_file_is_one_line(identified_session, tmp_path, immutable):
    d = shutil.copytree(identified_session, tmp_path / "s")
    refine = stage_path(d, "refine")
    immutable(refine)
    r = CliRunner().invoke(app, ["identify", str(d), "--force", "--no-report"])
    _one_line(r, f"{refine}: Operation not permitted")  # was exit 70 (PermissionError)


@pytest.mark.parametrize("command", ["export", "fk"])
def test_an_output_name_too_long_is_one_line(identified_session, tmp_path, command):
    d = shutil.copytree(identified_session, tmp_path / "s")
    out = tmp_path / ("n" * 300 + ".out")
    q = tmp_path / "q.csv"
    q.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,-90,90,0,0,0\n")
    args = {
        "export": ["export", str(d), "--format", "dh"],
        "fk": ["fk", str(d), "--q-file", str(q)],
    }
    r = CliRunner().invoke(app, [*args[command], "--out", str(out)])
    _one_line(r, "File name too long")  # was exit 70 (OSError)


@pytest.mark.parametrize("command", ["import", "simulate"])
def test_a_dangling_symlink_as_the_session_folder_says_so(tmp_path: Path, command: str) -> None:
    src = tmp_path / "two.txt"
    src.write_text(sscanss2_text(TWO_LINK, TWO_LINK_VALUES))
    link = tmp_path / "s"
    link.symlink_to(tmp_path / "gone")
    args = {"import": ["import", str(src), str(link), "--format", "sscanss2"],
            "simulate": ["simulate", str(link)]}[command]  # fmt: skip
    r = CliRunner().invoke(app, [*args, "--robot", str(TWO_LINK)])
    _one_line(r, f"{link} is a symbolic link to {tmp_path / 'gone'}, which does not exist")
    assert "File exists" not in r.stderr


def test_validate_says_how_many_rows_it_skipped(tmp_path: Path) -> None:
    text = sscanss2_text(TWO_LINK, TWO_LINK_VALUES, digits=15)
    src = tmp_path / "two.txt"
    src.write_text(text)
    cli = CliRunner()
    s = tmp_path / "s"
    for args in (["import", str(src), str(s), "--format", "sscanss2", "--robot", str(TWO_LINK)],
                 ["identify", str(s), "--no-report"]):  # fmt: skip
        assert cli.invoke(app, args).exit_code == 0
    rows = [line.split("\t") for line in text.splitlines()]
    rows[2][1], rows[5][3] = "nan", "inf"
    bad = tmp_path / "bad.txt"
    bad.write_text("\n".join("\t".join(r) for r in rows) + "\n")
    r = cli.invoke(app, ["validate", str(s), "--against", str(bad), "--format", "sscanss2"])
    assert r.exit_code == 0, r.output
    assert f"{len(rows) - 2} points" in r.stdout
    assert "warning: 2 row(s) of bad.txt skipped" in r.stderr  # was silent


def test_show_says_when_a_stage_table_was_edited(identified_session: Path, tmp_path: Path) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    r = CliRunner().invoke(app, ["show", str(d), "features"])
    assert r.exit_code == 0 and "warning" not in r.stderr, r.output
    edited = edit_arrow_value(stage_path(d, "features"), np.random.default_rng(0))
    assert edited
    r = CliRunner().invoke(app, ["show", str(d), "features"])
    assert r.exit_code == 0, r.output
    assert r.stderr.startswith("warning: ") and len(r.stderr.splitlines()) == 1, r.stderr
    assert "differs from the hash recorded when it was written" in r.stderr
    assert f"pipeline identify {d} --force" in r.stderr
