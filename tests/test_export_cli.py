"""`pipeline export` on the command line: outputs, and bad input as one line (exit 1)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

from pipeline.cli import EXIT_REFUSED, EXIT_USAGE, app
from pipeline.signature.checks import DIGEST_KEY
from pipeline.signature.file import signature_text


def invoke(*args: str) -> Result:
    return CliRunner().invoke(app, ["export", *args])


def assert_one_error(r: Result, *fragments: str) -> None:
    assert r.exit_code == EXIT_REFUSED, (r.exit_code, r.output)
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])


@pytest.fixture
def session(identified_session: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(identified_session, tmp_path / "s"))


def test_default_path_and_json_summary(session: Path) -> None:
    r = invoke(str(session), "--format", "urdf")
    assert r.exit_code == 0, r.output
    path = session / "export" / "signature.urdf"
    assert path.is_file() and f"wrote {path}" in r.stdout
    # The default file is armsig's own: rewritten without --force.
    r = invoke(str(session), "--format", "dh", "--design", "--frame", "design-base", "--json")
    assert r.exit_code == 0, r.output
    s = json.loads(r.stdout)
    assert s["path"] == str(session / "export" / "design.design-base.dh.json")
    assert (s["format"], s["model"], s["frame"]) == ("dh", "design", "design-base")
    assert s["max_position_error_m"] <= 1e-9 and s["configurations"] == 1000
    assert invoke(str(session), "--format", "urdf").exit_code == 0
    assert not list((session / "export").glob(".*.tmp"))  # written through a temp file


def test_unknown_format_and_frame(session: Path) -> None:
    """Choices are enums (issue 30 item 6): a wrong one is a usage error (exit 2) that
    lists them, as typer's own parser words it."""
    for args, choices in (
        (("--format", "sdf"), "'urdf', 'dh', 'mdh', 'json'"),
        (("--format", "urdf", "--frame", "world"), "'sensor', 'design-base'"),
    ):
        r = invoke(str(session), *args)
        assert r.exit_code == EXIT_USAGE, r.output
        lines = r.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and choices in lines[0]
    assert not (session / "export").exists()


def test_missing_signature(session: Path) -> None:
    (session / "signature.json").unlink()
    r = invoke(str(session), "--format", "urdf")
    assert_one_error(r, "cannot read signature", "pipeline identify")


def test_stale_signature(session: Path) -> None:
    path = session / "signature.json"
    doc = json.loads(path.read_text())
    del doc[DIGEST_KEY]
    doc["provenance"]["stages"]["frames"] = "0" * 64  # intact file, other stage outputs
    path.write_text(signature_text(doc))
    r = invoke(str(session), "--format", "dh")
    assert_one_error(r, "does not match the session's stages", "pipeline identify")
    assert not (session / "export").exists()


def test_out_in_a_missing_folder_or_a_folder(session: Path, tmp_path: Path) -> None:
    r = invoke(str(session), "--format", "urdf", "--out", str(tmp_path / "no" / "r.urdf"))
    assert_one_error(r, "--out", "does not exist")
    assert_one_error(invoke(str(session), "--format", "urdf", "--out", str(tmp_path)), "folder")


def test_existing_out_needs_force(session: Path, tmp_path: Path) -> None:
    out = tmp_path / "mine.urdf"
    out.write_text("the user's file")
    r = invoke(str(session), "--format", "urdf", "--out", str(out))
    assert_one_error(r, "already exists", "--force")
    assert out.read_text() == "the user's file"
    assert invoke(str(session), "--format", "urdf", "--out", str(out), "--force").exit_code == 0
    assert out.read_text().startswith("<?xml")


def test_read_only_out_folder(session: Path, read_only_dir: Path) -> None:
    r = invoke(str(session), "--format", "urdf", "--out", str(read_only_dir / "r.urdf"))
    assert_one_error(r, "cannot write in")


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc")
def test_unwritable_out_folder_even_for_root(session: Path) -> None:
    r = invoke(str(session), "--format", "urdf", "--out", "/proc/armsig-export.urdf")
    assert_one_error(r, "--out", "cannot write in")


def test_urdf_names_that_would_clash_are_refused() -> None:
    from dataclasses import replace

    from pipeline.errors import ArmsigError
    from pipeline.export.urdf import link_names
    from pipeline.robots import get_robot

    robot = get_robot("scara")
    assert link_names(robot)[0] == "base_link" and link_names(robot)[-1] == "tool"
    for name, kind in (("base", "link"), ("tool_joint", "joint")):
        bad = replace(robot, joints=(replace(robot.joints[0], name=name), *robot.joints[1:]))
        with pytest.raises(ArmsigError, match=f"two {kind}s named"):
            link_names(bad)
