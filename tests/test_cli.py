"""CLI: thin commands, errors become one line and exit code 1."""

from typer.testing import CliRunner

from pipeline.cli import app

runner = CliRunner()


def test_help_lists_commands() -> None:
    r = runner.invoke(app, ["--help"])
    assert r.exit_code == 0 and "robots" in r.output and "fk" in r.output


def test_robots() -> None:
    r = runner.invoke(app, ["robots"])
    assert r.exit_code == 0 and "puma560" in r.output and "stanford" in r.output


def test_fk_puma_upright() -> None:
    r = runner.invoke(app, ["fk", "puma560", "--q", "0 -90 90 0 0 0"])
    assert r.exit_code == 0
    # Arm straight up: 67.4 + 43.18 + 43.37 + 5.715 cm.
    assert "159.665" in r.output


def test_fk_errors_are_one_line() -> None:
    r = runner.invoke(app, ["fk", "puma560", "--q", "0 0"])
    assert r.exit_code == 1
    assert "expected 6 values" in r.output and len(r.output.strip().splitlines()) == 1
    r = runner.invoke(app, ["fk", "nope", "--q", "0"])
    assert r.exit_code == 1 and "unknown robot" in r.output
    r = runner.invoke(app, ["fk", "puma560", "--q", "a b"])
    assert r.exit_code == 1 and "must hold numbers" in r.output
