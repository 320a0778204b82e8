"""The design-model baseline beside the signature on measured points (issue 29, item 4):
stage ``validation``'s ``design_error_cm``, the report, ``identify --json`` and ``fleet``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.fleet.row import session_row
from pipeline.identify import identify
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.rig.true_robot import ErrorSigmas
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table


def _session(d: Path, **opts) -> Path:
    options = {"sensor": "tracker", "poses": 40, "sweeps": False, "check": 20, "seed": 5, **opts}
    simulate_session(d, SimulationOptions(**options))
    identify(d, report=True)
    return d


def test_before_and_after_on_fit_and_check_points(tmp_path) -> None:
    d = _session(tmp_path / "s")
    rows = read_table(stage_path(d, "validation")).to_pylist()
    roles = {r["role"] for r in rows}
    assert roles == {"fit", "check"}
    for role in roles:
        sig = np.array([r["error_cm"] for r in rows if r["role"] == role])
        design = np.array([r["design_error_cm"] for r in rows if r["role"] == role])
        # the simulated robot's geometric errors: the design misses by far more
        assert np.sqrt(np.mean(design**2)) > 5 * np.sqrt(np.mean(sig**2))
    r = CliRunner().invoke(app, ["identify", str(d), "--json"])
    v = json.loads(r.stdout)["validation"]
    assert v["check"]["n"] == 20 and v["check"]["design_registered_rms_cm"] > v["check"]["rms_cm"]
    row = session_row(d, "validate")
    assert row["check_design_rms_cm"] == v["check"]["design_registered_rms_cm"]
    assert row["fit_design_rms_cm"] == v["fit"]["design_registered_rms_cm"]
    assert "design model, registered RMS" in (d / "report" / "report.md").read_text()


def test_a_robot_built_to_its_design_has_no_before(tmp_path) -> None:
    """Noiseless, no kinematic error: the registered design model is the robot, exactly."""
    d = _session(tmp_path / "p", noiseless=True, sigmas=ErrorSigmas(0.0, 0.0, 0.0))
    design = [r["design_error_cm"] for r in read_table(stage_path(d, "validation")).to_pylist()]
    assert max(design) < 1e-9
