"""CLI conventions (issue 16): --version, ``python -m pipeline``, --json on stdout that
jq parses with errors one line on stderr, a progress line on stderr, status without the
evaluate stages before an evaluation recording, and ``fk`` on a session's signature."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from pipeline import __version__
from pipeline.cli import app
from pipeline.identify import identify
from pipeline.robots import get_robot
from pipeline.robots.fk import design_pose
from pipeline.signature.session import load_session_signature
from pipeline.stages.catalog import EVALUATE_STAGE_MODULES
from pipeline.stages.runner import stage_path

ROOT = Path(__file__).resolve().parent.parent
runner = CliRunner()
Q = "10 -80 100 5 20 30"  # deg, inside the Puma's limits


def _module(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pipeline", *args], capture_output=True, text=True, check=False
    )


def _parse(text: str) -> Any:
    """``text`` as JSON, through jq when it is installed (else Python's parser)."""
    if shutil.which("jq"):
        out = subprocess.run(["jq", "-c", "."], input=text, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
    return json.loads(text)


def _session(identified_session: Path, tmp_path: Path) -> Path:
    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    return d


def test_version() -> None:
    r = runner.invoke(app, ["--version"])
    assert r.exit_code == 0 and r.stdout == f"armsig {__version__}\n"


def test_python_m_pipeline_is_the_same_app() -> None:
    helped = _module("--help")
    assert helped.returncode == 0 and "identify" in helped.stdout
    assert _module("--version").stdout == f"armsig {__version__}\n"
    bad = _module("no-such-command")
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr.startswith("error:") and len(bad.stderr.splitlines()) == 1


def test_identify_and_status_json(identified_session: Path, tmp_path: Path) -> None:
    d = _session(identified_session, tmp_path)
    r = runner.invoke(app, ["identify", str(d), "--json", "--no-report", "--from", "dh"])
    assert r.exit_code == 0, r.output
    doc = _parse(r.stdout)
    actions = {s["name"]: s["action"] for s in doc["stages"]}
    assert actions["session"] == "cached" and actions["dh"] == "ran"
    assert doc["signature"] == str(d / "signature.json") and doc["report"] is None
    r = runner.invoke(app, ["status", str(d), "--json"])
    assert r.exit_code == 0, r.output
    states = _parse(r.stdout)
    assert {s["state"] for s in states} == {"fresh"} and states[-1]["name"] == "signature"


def test_json_errors_stay_one_line_on_stderr(tmp_path: Path) -> None:
    for cmd in ("identify", "status", "audit", "ik", "evaluate"):
        r = runner.invoke(app, [cmd, str(tmp_path / "nothing"), "--json"])
        assert r.exit_code == 1, (cmd, r.output)
        assert r.stdout == "" and len(r.stderr.splitlines()) == 1, cmd


def test_status_shows_evaluate_stages_once_there_is_an_evaluation(
    identified_session: Path, tmp_path: Path
) -> None:
    d = _session(identified_session, tmp_path)
    names = [s["name"] for s in _parse(runner.invoke(app, ["status", str(d), "--json"]).stdout)]
    assert not set(EVALUATE_STAGE_MODULES) & set(names)
    assert "evaluate_" not in runner.invoke(app, ["status", str(d)]).stdout
    shutil.copy(ROOT / "sessions/robot1/evaluation.mcap", d / "evaluation.mcap")
    states = _parse(runner.invoke(app, ["status", str(d), "--json"]).stdout)
    assert [s["name"] for s in states][-4:] == list(EVALUATE_STAGE_MODULES)
    assert {s["state"] for s in states[-4:]} == {"missing"}


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_identify_progress_line(identified_session: Path, tmp_path: Path) -> None:
    d = _session(identified_session, tmp_path)
    r = runner.invoke(app, ["identify", str(d), "--no-report", "--from", "frames"])
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.split("\n") if not ln.startswith("warning:")]
    assert len(lines) == 2 and lines[1] == ""  # not a terminal: one summary line, no \r
    assert lines[0].startswith("identify ") and "16/16 stages" in lines[0]
    term = _Terminal()
    identify(d, force=True, report=False, progress=term)
    text = term.getvalue()
    assert text.count("\r") == 16 and "16/16 stages" in text  # redrawn after each stage
    assert text.count("\n") == 1 and text.endswith("\n")


def _pose(out: str) -> list[float]:
    """x y z (cm) rx ry rz (deg) of `pipeline fk` output."""
    rows = {ln.split("=")[0].strip(): ln.split("=")[1] for ln in out.splitlines() if "=" in ln}
    return [float(v) for k in ("xyz_cm", "rpy_deg") for v in rows[k].strip(" []").split()]


def test_fk_session_round_trips_through_ik_json(identified_session: Path) -> None:
    d = str(identified_session)
    r = runner.invoke(app, ["fk", d, "--q", Q])
    assert r.exit_code == 0, r.output
    pose = _pose(r.stdout)
    r = runner.invoke(app, ["ik", d, "--pose", *map(repr, pose), "--near", Q, "--json"])
    assert r.exit_code == 0, r.output
    doc = _parse(r.stdout)
    assert doc["status"] == "converged" and doc["converged"] is True
    assert doc["units"] == ["deg"] * 6 and len(doc["joints"]) == 6
    # One encoder count of the Puma is ~0.005 deg; the pose was printed to 1e-6.
    np.testing.assert_allclose(doc["q"], [float(v) for v in Q.split()], atol=1e-3)
    assert doc["position_error_cm"] < 1e-3


def test_fk_session_design_is_the_design_flange_times_the_tool(identified_session: Path) -> None:
    d = str(identified_session)
    sig = load_session_signature(identified_session / "signature.json")
    flange = design_pose(get_robot("puma560"), [float(v) for v in Q.split()]).matrix
    want = flange @ sig.design_flange_to_tool
    r = runner.invoke(app, ["fk", d, "--q", Q, "--design"])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(_pose(r.stdout)[:3], want[:3, 3], atol=1e-5)
    signature = _pose(runner.invoke(app, ["fk", d, "--q", Q]).stdout)
    assert np.abs(np.array(signature[:3]) - want[:3, 3]).max() > 1e-2  # they differ


def test_fk_refuses_a_stale_signature(identified_session: Path, tmp_path: Path) -> None:
    d = _session(identified_session, tmp_path)
    stage_path(d, "smodel").unlink()
    r = runner.invoke(app, ["fk", str(d), "--q", Q])
    assert r.exit_code == 1 and "signature.json" in r.stderr and len(r.stderr.splitlines()) == 1
    assert r.stdout == ""


def test_a_signature_of_an_older_armsig_is_refused(
    identified_session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 32 item 1: after an upgrade that changes what a stage computes, the
    signature its old stages built is refused in one line naming the stage and the
    command that rebuilds it (stage ``refine`` pretended one version newer)."""
    import dataclasses

    import pipeline.stages.refine as refine_stage
    import pipeline.stages.refine_points as refine_points

    d = _session(identified_session, tmp_path)
    assert runner.invoke(app, ["fk", str(d), "--q", Q]).exit_code == 0
    for module in (refine_stage, refine_points):
        newer = dataclasses.replace(module.STAGE, version=module.STAGE.version + 1)
        monkeypatch.setattr(module, "STAGE", newer)
    r = runner.invoke(app, ["fk", str(d), "--q", Q])
    assert r.exit_code == 1 and len(r.stderr.splitlines()) == 1, r.output
    assert "built by an older armsig (stage refine version" in r.stderr
    assert f"pipeline identify {d}" in r.stderr and r.stdout == ""


@pytest.mark.parametrize("robot", ["puma560", str(ROOT / "pipeline/robots/data/scara.toml")])
def test_fk_robot_still_works(robot: str) -> None:
    r = runner.invoke(app, ["fk", robot, "--q", " ".join(["0"] * get_robot(robot).n_joints)])
    assert r.exit_code == 0, r.output
    assert "xyz_cm" in r.stdout


def test_shell_completion() -> None:
    """The protocol a shell's completion script speaks (--show-completion prints that
    script for the shell it detects; a test process may have none, so not tested)."""
    env = {"_PIPELINE_COMPLETE": "complete_bash", "COMP_WORDS": "pipeline iden", "COMP_CWORD": "1"}
    cmd = [sys.executable, "-m", "pipeline"]
    done = subprocess.run(cmd, env={**os.environ, **env}, capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.split() == ["identify"]


def test_ik_json_when_not_reached(identified_session: Path, tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.ipc as ipc

    d = str(identified_session)
    far = ["500", "0", "0", "0", "0", "0"]  # cm: beyond the Puma's reach
    r = runner.invoke(app, ["ik", d, "--pose", *far, "--json"])
    assert r.exit_code == 3, r.output
    doc = _parse(r.stdout)
    assert doc["converged"] is False and doc["status"] != "converged" and len(doc["q"]) == 6
    pose = _pose(runner.invoke(app, ["fk", d, "--q", Q]).stdout)
    cols = ("x_cm", "y_cm", "z_cm", "rx_deg", "ry_deg", "rz_deg")
    targets = pa.table({c: [v, float(f)] for c, v, f in zip(cols, pose, far, strict=True)})
    with ipc.new_file(str(tmp_path / "t.arrow"), targets.schema) as w:
        w.write_table(targets)
    out = tmp_path / "q.arrow"
    cmd = ["ik", d, "--targets", str(tmp_path / "t.arrow"), "--out", str(out), "--json"]
    r = runner.invoke(app, [*cmd, "--near", Q])
    assert r.exit_code == 3, r.output
    doc = _parse(r.stdout)
    assert (doc["targets"], doc["converged"], doc["failed"], doc["out"]) == (2, 1, 1, str(out))
