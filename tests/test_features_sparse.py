"""Sparse and short sweeps (issue 14): exact fits, expected accuracy, warnings, refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import polars as pl
import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.contract.channels import POINT_CHANNELS
from pipeline.features.accuracy import revolute_accuracy
from pipeline.features.circle import fit_circle
from pipeline.features.expected import (
    SIGMA_COLUMNS,
    noise_bound,
    prismatic_expected,
    revolute_expected,
)
from pipeline.features.line import fit_line
from pipeline.features.plane import fit_plane_lsq, orient_normal
from pipeline.identify import identify
from pipeline.rig.audit import audit
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.stages.runner import stage_path
from tests.feature_data import arc, cross_angle
from tests.recording_data import read_raw, write_raw


def _revolute(p: np.ndarray):
    plane = fit_plane_lsq(p)
    circle = fit_circle(p, plane)
    acc = revolute_accuracy(p, plane, circle)
    thesis = (float(acc.sigma_delta_empirical), float(acc.sigma_c))
    return plane, circle, revolute_expected(p, plane, circle, thesis)


# (points, sweep, noise gain computed once from these evenly spaced arcs, basis)
SPARSE = [(5, 60.0, 8.0, "propagated"), (7, 120.0, 1.98, "propagated"), (11, 360.0, 0.447, None)]


@pytest.mark.parametrize(("n", "sweep", "gain", "basis"), SPARSE)
def test_sparse_short_noiseless_sweeps_are_exact(n: int, sweep: float, gain: float, basis) -> None:
    p, normal, center = arc(np.random.default_rng(n), n, sweep, 30.0)
    plane, circle, exp = _revolute(p)
    assert cross_angle(orient_normal(plane.normal, p), normal) < 1e-12
    assert np.linalg.norm(circle.center - center) < 1e-9
    assert exp.residual_dof == n - 3
    assert exp.noise_gain == pytest.approx(gain, rel=0.01)
    assert exp.basis == (basis or "(6.12)/(6.13)")
    assert exp.axis_deg is not None and exp.axis_deg < 1e-9  # noiseless: ~0, and known
    short = [w for w in exp.warnings if "noise gain > 1" in w]
    assert bool(short) == (gain > 1.0), exp.warnings


def test_propagated_accuracy_matches_monte_carlo() -> None:
    """7 points over 120°, σ = 0.01 cm: the stated axis and centre σ are those observed."""
    rng = np.random.default_rng(3)
    p, normal, center = arc(rng, 7, 120.0, 30.0)
    noisy = p + rng.normal(0.0, 0.01, (2000, 7, 3))
    plane = fit_plane_lsq(noisy)
    circle = fit_circle(noisy, plane)
    u = np.cross(normal, [1.0, 0.0, 0.0])
    uv = np.stack([u, np.cross(normal, u)]) / np.linalg.norm(u)
    tilts = orient_normal(plane.normal, noisy) @ uv.T  # (trials, 2) rad
    observed_axis = np.degrees(np.sqrt(np.linalg.eigvalsh(np.cov(tilts.T))[-1]))
    observed_center = np.sqrt(np.linalg.eigvalsh(np.cov((circle.center - center).T))[-1])
    stated = [_revolute(q)[2] for q in noisy[:500]]  # each from its own fitted σ (4 dof)
    stated_axis = np.sqrt(np.mean([e.axis_deg**2 for e in stated]))
    stated_center = np.sqrt(np.mean([e.center_cm**2 for e in stated]))
    assert stated_axis == pytest.approx(observed_axis, rel=0.15)
    assert stated_center == pytest.approx(observed_center, rel=0.15)


def test_three_points_leave_the_accuracy_unknown_not_zero() -> None:
    p, _, _ = arc(np.random.default_rng(1), 3, 200.0, 30.0)
    p = p + np.random.default_rng(2).normal(0.0, 0.01, p.shape)
    _, _, exp = _revolute(p)
    assert exp.residual_dof == 0 and exp.basis == "unknown"
    assert exp.axis_deg is None and exp.center_cm is None
    cols = exp.columns()
    assert all(cols[k] is None for k in SIGMA_COLUMNS)
    assert any("unknown, not 0" in w for w in exp.warnings)


def test_four_points_warn_that_the_noise_is_barely_known() -> None:
    p, _, _ = arc(np.random.default_rng(1), 4, 300.0, 30.0)
    p = p + np.random.default_rng(2).normal(0.0, 0.01, p.shape)
    _, _, exp = _revolute(p)
    assert exp.residual_dof == 1 and exp.axis_deg is not None and exp.axis_deg > 0
    assert any("31.9x the fitted one" in w for w in exp.warnings), exp.warnings
    # The threshold: the 95 % bound passes 2 between 7 and 8 degrees of freedom.
    assert noise_bound(7) > 2.0 > noise_bound(8)


def test_prismatic_expected_accuracy() -> None:
    t = np.linspace(0.0, 20.0, 5)
    p = np.array([1.0, 2.0, 3.0]) + t[:, None] * np.array([0.0, 0.6, 0.8])
    p = p + np.random.default_rng(0).normal(0.0, 0.01, p.shape)
    exp = prismatic_expected(p, fit_line(p))
    assert exp.residual_dof == 6 and exp.basis == "propagated" and exp.noise_gain <= 1.0
    assert exp.center_cm is not None and 0 < exp.center_cm < 0.05
    assert any("residual degrees of freedom" in w for w in exp.warnings)  # 6 < 8


def test_collinear_revolute_sweep_is_refused_in_one_line(tmp_path: Path) -> None:
    src = tmp_path / "src"
    simulate_session(src, SimulationOptions(sensor="tracker", seed=2, noiseless=True, points=5))
    raw, _ = read_raw(src / "recording.mcap")
    out = []
    for m in raw:  # sweep 2's target moves on a straight line
        p = m.payload
        if m.topic == "/points" and p["sweep"] == 2:
            p.update(x_cm=10.0 + 5.0 * p["step"], y_cm=20.0, z_cm=30.0)
            m = m.with_payload(p)
        out.append(m)
    (tmp_path / "s").mkdir()
    write_raw(tmp_path / "s" / "recording.mcap", out, channels=POINT_CHANNELS)
    r = CliRunner().invoke(app, ["identify", str(tmp_path / "s")])
    assert r.exit_code == 1, r.output
    lines = [ln for ln in r.output.splitlines() if ln.startswith("error")]
    assert len(lines) == 1 and "sweep 2: no usable target" in lines[0], r.output
    assert "collinear" in lines[0], r.output


@pytest.fixture(scope="module")
def short_session(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("short")
    simulate_session(d, SimulationOptions(seed=5, noiseless=True, points=5, repeats=1,
                                          max_sweep_deg=60.0))  # fmt: skip
    return d


def test_five_points_over_60_deg_identify_exactly_and_warn(short_session: Path) -> None:
    r = CliRunner().invoke(app, ["identify", str(short_session)])
    assert r.exit_code == 0, r.output
    assert "warning: joint 1: sweep 60° with 5 points" in r.output  # the summary output
    assert audit(short_session, configurations=200).signature.max_position_cm <= 1e-6
    feats = pl.read_ipc(stage_path(short_session, "features"))
    assert (feats["expected_basis"] == "propagated").all()
    assert (feats["noise_gain"] > 1).all()
    report = (short_session / "report" / "report.md").read_text()
    assert "## Expected feature accuracy (6.12)/(6.13)" in report
    assert "| 1 | waist | 5 | 60.000° | 2 | 8 |" in report


def test_seven_points_over_120_deg_identify_exactly(tmp_path: Path) -> None:
    opts = SimulationOptions(seed=6, noiseless=True, points=7, repeats=1, max_sweep_deg=120.0)
    simulate_session(tmp_path, opts)
    result = identify(tmp_path, report=False)
    assert any("sweep 120° with 7 points" in w for w in result.warnings)
    assert audit(tmp_path, configurations=200).signature.max_position_cm <= 1e-6


def test_three_point_session_reports_no_zero_sigma(tmp_path: Path) -> None:
    simulate_session(tmp_path, SimulationOptions(seed=5, points=3, repeats=2))
    result = identify(tmp_path)  # the report too: its summary sorts by a null σ_normal
    feats = pl.read_ipc(stage_path(tmp_path, "features"))
    assert (feats["expected_basis"] == "unknown").all()
    assert feats["sigma_normal_cm"].null_count() == len(feats)
    assert sum("unknown, not 0" in w for w in result.warnings) == len(feats)
    report = (tmp_path / "report" / "report.md").read_text()
    assert "| 1 | waist | 3 | 300.052° | 0 | 1.42 | — | — | unknown |" in report


def test_prismatic_sweep_with_two_usable_points_is_one_line(tmp_path: Path) -> None:
    simulate_session(tmp_path, SimulationOptions(robot="stanford", seed=2, noiseless=True,
                                                 points=3, repeats=1))  # fmt: skip
    messages, meta = read_raw(tmp_path / "recording.mcap")
    out = []
    for m in messages:  # sweep 3 (the boom) step 1: no echo at all
        pl_ = m.payload
        if m.topic == "/sonic/ranges" and pl_["sweep"] == 3 and pl_["step"] == 1:
            pl_["ranges_cm"] = [[None] * len(row) for row in pl_["ranges_cm"]]
            m = m.with_payload(pl_)
        out.append(m)
    write_raw(tmp_path / "recording.mcap", out)
    r = CliRunner().invoke(app, ["identify", str(tmp_path)])
    assert r.exit_code == 1, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert any("sweep 3: 2 usable target positions" in ln for ln in lines), r.output
    assert sum(ln.startswith("error") for ln in lines) == 1, r.output
