"""The verdict end to end: identify's last line, the report's first section, the fleet row.

Skipped (with the reason) until the stages ``uncertainty``, ``holdout`` and ``verdict`` are
in the identification stage lists: they need the ``refine`` and ``chain`` stages of branch
``refinecore``, merged by the integrator; after that these tests run and can fail.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from pipeline.cli import EXIT_VERDICT_FAIL, app
from pipeline.fleet.row import session_row
from pipeline.report.identification import write_report
from pipeline.stages.catalog import identification_names
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table

runner = CliRunner()
pytestmark = pytest.mark.skipif(
    "verdict" not in identification_names("sonic"),
    reason="stage verdict not registered yet (needs refinecore's refine/chain stages)",
)


def test_identify_prints_the_verdict_last(identified_session: Path, tmp_path: Path) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    r = runner.invoke(app, ["identify", str(d), "--no-report"])
    assert r.exit_code == 0, r.output
    last = r.stdout.strip().splitlines()[-1]
    v = read_table(stage_path(d, "verdict")).to_pylist()[0]
    assert last == f"s: {v['line']}"
    assert v["verdict"] in ("PASS", "CHECK", "FAIL")
    assert last.startswith(f"s: {v['verdict']}  predicted ")
    assert " cm RMS (95 % " in last and "held-out " in last and "(predicted there " in last


def test_a_verdict_parameter_changes_the_line(identified_session: Path, tmp_path: Path) -> None:
    """A threshold below the session's predicted error: FAIL, with that reason, exit 4."""
    d = shutil.copytree(identified_session, tmp_path / "s")
    r = runner.invoke(
        app, ["identify", str(d), "--no-report", "--param", "verdict.max_predicted_rms_reach=1e-8"]
    )
    assert r.exit_code == EXIT_VERDICT_FAIL, r.output
    last = r.stdout.strip().splitlines()[-1]
    assert last.startswith("s: FAIL  predicted ") and "> 1.766e-06 cm" in last


def test_report_starts_with_the_verdict(identified_session: Path, tmp_path: Path) -> None:
    d = shutil.copytree(identified_session, tmp_path / "s")
    text = write_report(d).read_text(encoding="utf-8")
    sections = [line for line in text.splitlines() if line.startswith("## ")]
    assert sections[0].startswith("## Verdict: ")
    assert "| predicted RMS tool error over the workspace (cm) |" in text
    assert "![predicted tool error over the workspace](uncertainty.png)" in text
    assert (d / "report" / "uncertainty.png").stat().st_size > 1000


def test_fleet_row_has_the_verdict(identified_session: Path) -> None:
    row = session_row(identified_session, "identify")
    v = read_table(stage_path(identified_session, "verdict")).to_pylist()[0]
    assert row["verdict"] == v["verdict"] and row["verdict_reasons"] == v["reasons"]
    assert row["predicted_rms_cm"] == v["predicted_rms_cm"] > 0
