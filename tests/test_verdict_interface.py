"""The verdict as an interface (issue 30 item 2): ``identify`` exits 4 on FAIL and gives the
verdict as data in ``--json``; ``export`` and ``ik`` refuse a FAIL signature unless
``--accept-verdict`` and warn on CHECK; a signature without a verdict is used as before."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import Result
from typer.testing import CliRunner

from pipeline.cli import EXIT_VERDICT_FAIL, app
from pipeline.control.poses import tool_pose
from pipeline.errors import VerdictFailError
from pipeline.signature.verdict import verdict_from_row, verdict_gate

runner = CliRunner()
FAIL_PARAM = "verdict.max_predicted_rms_reach=1e-8"  # below any session's predicted error
CHECK_PARAM = "verdict.chi2_check=0.5"  # below a clean session's χ²/dof ~0.9


def _identify(d: Path, *extra: str) -> Result:
    return runner.invoke(app, ["identify", str(d), "--no-report", *extra])


@pytest.fixture(scope="module")
def failed(identified_session: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the identified session whose verdict is FAIL (one threshold lowered)."""
    d = shutil.copytree(identified_session, tmp_path_factory.mktemp("verdict") / "fail")
    assert _identify(d, "--param", FAIL_PARAM).exit_code == EXIT_VERDICT_FAIL
    return d


@pytest.fixture(scope="module")
def checked(identified_session: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = shutil.copytree(identified_session, tmp_path_factory.mktemp("verdict") / "check")
    assert _identify(d, "--param", CHECK_PARAM).exit_code == 0
    return d


def _pose(d: Path) -> list[str]:
    """A reachable pose of the session's tool: its pose at q = 0."""
    p = tool_pose(d, [0.0] * 6)
    return ["--pose", *(f"{v:.9f}" for v in (*p.xyz_cm, *p.rpy_deg))]


def test_identify_exits_4_on_fail_after_its_output(failed: Path) -> None:
    r = _identify(failed, "--param", FAIL_PARAM)  # cached: the same answer
    assert r.exit_code == EXIT_VERDICT_FAIL, r.output
    assert r.stdout.strip().splitlines()[-1].startswith("fail: FAIL  predicted ")
    assert (failed / "signature.json").is_file()
    err = [line for line in r.stderr.splitlines() if line.startswith("error: ")]
    assert len(err) == 1 and "verdict is FAIL (predicted RMS tool error" in err[0], r.stderr


def test_identify_json_carries_the_verdict_as_data(failed: Path) -> None:
    r = _identify(failed, "--param", FAIL_PARAM, "--json")
    assert r.exit_code == EXIT_VERDICT_FAIL, r.output
    doc = json.loads(r.stdout)
    v = doc["verdict_detail"]
    assert doc["verdict"].startswith("fail: FAIL") and v["status"] == "FAIL"
    first = v["reasons"][0]
    assert first["level"] == "FAIL" and first["rule"] == "max_predicted_rms_reach"
    limit = v["numbers"]["predicted_limit_cm"]
    assert limit == 1e-8 * v["numbers"]["design_reach_cm"] and first["threshold"] == limit
    assert first["value"] == v["numbers"]["predicted_rms_cm"] > limit
    assert "predicted RMS tool error" in first["text"]


def test_identify_check_and_pass_exit_0(identified_session: Path, checked: Path) -> None:
    r = _identify(checked, "--param", CHECK_PARAM, "--json")
    assert r.exit_code == 0, r.output
    v = json.loads(r.stdout)["verdict_detail"]
    assert v["status"] == "CHECK" and v["reasons"][-1]["rule"] == "chi2_check"
    r = _identify(identified_session, "--json")
    assert r.exit_code == 0 and json.loads(r.stdout)["verdict_detail"]["status"] == "PASS"


def test_export_refuses_a_fail_signature_unless_accepted(failed: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.urdf"
    r = runner.invoke(app, ["export", str(failed), "--format", "urdf", "--out", str(out)])
    assert r.exit_code == EXIT_VERDICT_FAIL and not out.exists(), r.output
    assert r.stderr.startswith("error: ") and len(r.stderr.splitlines()) == 1
    assert "verdict is FAIL" in r.stderr and "--accept-verdict" in r.stderr
    r = runner.invoke(
        app,
        [
            "export",
            str(failed),
            "--format",
            "urdf",
            "--out",
            str(out),
            "--accept-verdict",
            "--json",
        ],
    )
    assert r.exit_code == 0 and out.is_file(), r.output
    assert json.loads(r.stdout)["verdict"] == "FAIL"
    assert r.stderr.startswith("warning: ") and "(accepted by --accept-verdict)" in r.stderr


def test_ik_refuses_a_fail_signature_unless_accepted(failed: Path) -> None:
    r = runner.invoke(app, ["ik", str(failed), *_pose(failed)])
    assert r.exit_code == EXIT_VERDICT_FAIL and r.stdout == "", r.output
    assert "verdict is FAIL" in r.stderr and "--accept-verdict" in r.stderr
    r = runner.invoke(app, ["ik", str(failed), *_pose(failed), "--accept-verdict"])
    assert r.exit_code == 0 and r.stdout.startswith("q = "), r.output


def test_check_warns_on_stderr_and_keeps_json_stdout(checked: Path, tmp_path: Path) -> None:
    r = runner.invoke(app, ["ik", str(checked), *_pose(checked), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["verdict"] == "CHECK"
    assert r.stderr.startswith("warning: ") and "verdict is CHECK (χ²/dof" in r.stderr
    out = tmp_path / "s.dh.json"
    r = runner.invoke(app, ["export", str(checked), "--format", "dh", "--out", str(out)])
    assert r.exit_code == 0 and out.is_file() and "verdict is CHECK" in r.stderr, r.output


def test_pass_is_silent(identified_session: Path, tmp_path: Path) -> None:
    out = tmp_path / "s.urdf"
    args = ["export", str(identified_session), "--format", "urdf", "--out", str(out), "--json"]
    r = runner.invoke(app, args)
    assert r.exit_code == 0 and r.stderr == "", r.output
    assert json.loads(r.stdout)["verdict"] == "PASS"


def test_the_gate_without_a_verdict_and_on_an_older_row() -> None:
    assert verdict_gate(None, "s", accept=False) is None  # no verdict: as before
    old = {"verdict": "FAIL", "reasons": ["the refinement did not converge"], "line": "FAIL"}
    v = verdict_from_row(old)  # a stage version 2 row: no per-reason columns
    assert v is not None and v.reasons[0]["rule"] is None
    with pytest.raises(VerdictFailError, match="did not converge.*--accept-verdict"):
        verdict_gate(v, "s", accept=False)
    assert "accepted" in (verdict_gate(v, "s", accept=True) or "")


def test_compensate_refuses_a_fail_signature_and_warns_on_check(
    failed: Path, checked: Path, tmp_path: Path
) -> None:
    import pyarrow as pa
    import pyarrow.ipc as ipc

    from pipeline.control.targets import TARGET_COLUMNS

    pose = [float(v) for v in _pose(failed)[1:]]
    table = pa.table({c: [v] for c, v in zip(TARGET_COLUMNS, pose, strict=True)})
    targets = tmp_path / "t.arrow"
    with ipc.new_file(str(targets), table.schema) as w:
        w.write_table(table)
    out = tmp_path / "c.arrow"
    args = ["compensate", str(failed), "--targets", str(targets), "--out", str(out)]
    r = runner.invoke(app, args)
    assert r.exit_code == EXIT_VERDICT_FAIL and not out.exists(), r.output
    assert "verdict is FAIL" in r.stderr and "--accept-verdict" in r.stderr
    r = runner.invoke(app, [*args, "--accept-verdict", "--json"])
    assert r.exit_code == 0 and out.is_file(), r.output
    assert json.loads(r.stdout)["verdict"] == "FAIL" and "accepted" in r.stderr
    r = runner.invoke(app, ["compensate", str(checked), "--targets", str(targets), "--out",
                            str(tmp_path / "k.arrow")])  # fmt: skip
    assert r.exit_code == 0 and "verdict is CHECK" in r.stderr, r.output
