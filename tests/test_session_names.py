"""Session arguments as `simulate` and `import` name them (issue 30, item 5): `pipeline
simulate robot8` writes sessions/robot8, and every command taking a session then finds it
by the same NAME; a folder path is taken as given."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pipeline.cli import app

ROBOT3 = Path(__file__).resolve().parent.parent / "sessions" / "robot3"
runner = CliRunner()


@pytest.fixture()
def here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    (tmp_path / "sessions" / "robot8").mkdir(parents=True)
    for f in ("recording.mcap", "rig-truth.json"):
        shutil.copy(ROBOT3 / f, tmp_path / "sessions" / "robot8" / f)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_a_name_names_the_session_simulate_wrote(here: Path) -> None:
    r = runner.invoke(app, ["identify", "robot8", "--no-report"])
    assert r.exit_code == 0, r.output
    assert (here / "sessions" / "robot8" / "signature.json").is_file()
    pose = ["--pose", "40", "20", "60", "180", "0", "90"]
    for args in (["status", "robot8"], ["show", "robot8", "dh", "--rows", "1"],
                 ["audit", "robot8"], ["ik", "robot8", *pose],
                 ["export", "robot8", "--format", "dh"]):  # fmt: skip
        r = runner.invoke(app, args)
        assert r.exit_code == 0, (args, r.output)
    r = runner.invoke(app, ["fk", "robot8", "--q", "0 -90 90 0 0 0"])
    assert r.exit_code == 0 and "frame   = design-base" in r.output  # the session, not a robot
    r = runner.invoke(app, ["fk", "puma560", "--q", "0 -90 90 0 0 0"])
    assert r.exit_code == 0 and "frame   = base" in r.output  # a built-in name stays a robot


def test_a_folder_here_is_taken_as_given(here: Path) -> None:
    shutil.copytree(here / "sessions" / "robot8", here / "robot8")  # ./robot8 beside sessions/
    r = runner.invoke(app, ["identify", "robot8", "--no-report"])
    assert r.exit_code == 0, r.output
    assert (here / "robot8" / "signature.json").is_file()
    assert not (here / "sessions" / "robot8" / "signature.json").exists()


def test_an_unknown_name_says_where_it_looked(here: Path) -> None:
    r = runner.invoke(app, ["identify", "robot9"])
    assert r.exit_code == 1
    assert "no folder robot9 here, nor sessions/robot9" in r.output and r.output.count("\n") == 1
