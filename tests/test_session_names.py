"""Session arguments as `simulate` and `import` name them (issue 30, item 5): `pipeline
simulate robot8` writes sessions/robot8, and every command taking a session then finds it
by the same NAME; a folder path is taken as given."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pipeline.cli import EXIT_REFUSED, app

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


LONG = "n" * 300  # a name over the file system's 255 bytes
SESSION_COMMANDS = {
    "identify": [], "status": [], "show": [], "audit": [], "evaluate": [],
    "validate": ["--against", "x.csv", "--format", "table"], "fk": ["--q", "0 0 0 0 0 0"],
    "ik": ["--pose", "40", "20", "60", "180", "0", "90"], "ik-convergence": [],
    "compensate": ["--targets", "t.arrow", "--out", "o.arrow"], "viz": [],
    "export": ["--format", "dh"],
}  # fmt: skip


@pytest.mark.parametrize("command", SESSION_COMMANDS)
@pytest.mark.parametrize("name", [LONG, f"sessions/{LONG}", f"/tmp/{LONG}/s", "é" * 128])
def test_a_session_name_over_255_bytes_is_one_line(
    command: str, name: str, tmp_path: Path, monkeypatch
) -> None:
    """Issue 44: every session command died with "File name too long" (exit 70)."""
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(app, [command, name, *SESSION_COMMANDS[command]])
    assert r.exit_code == EXIT_REFUSED, (r.exit_code, r.output)
    assert r.stderr.count("\n") == 1 and "at most 255 bytes" in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [["simulate", LONG], ["plan", "p.csv", "--from", LONG]])
def test_a_new_or_planned_session_name_over_255_bytes_is_one_line(
    argv: list[str], tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(app, argv)
    assert r.exit_code == EXIT_REFUSED and r.stderr.count("\n") == 1, r.output
    assert "255 bytes" in r.stderr and list(tmp_path.iterdir()) == []
