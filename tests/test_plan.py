"""`pipeline plan` (issue 28): a pose set chosen for the smallest predicted tool error, the
file a robot program reads, and `pipeline simulate --plan` recording exactly it."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.planning import plan_poses, write_plan
from pipeline.rig.audit import audit
from pipeline.rig.pose_file import read_pose_plan
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots import get_robot
from pipeline.stages.frames import sweep_readings
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table
from pipeline.sweeps import POSES_SWEEP


@pytest.fixture(scope="module")
def puma_plan():
    return plan_poses(get_robot("puma560"), 24, candidates=2000)


def test_a_plan_predicts_less_error_than_as_many_random_poses(puma_plan) -> None:
    assert len(puma_plan.q) == 24
    assert puma_plan.rms_cm < 0.85 * puma_plan.random_rms_cm
    assert np.all(np.diff(puma_plan.rms_by_size_cm) <= 1e-15)  # each pose helps
    assert puma_plan.unidentified == ()
    lim = get_robot("puma560").limits
    assert ((puma_plan.q >= lim[:, 0]) & (puma_plan.q <= lim[:, 1])).all()


def test_a_target_stops_the_plan_at_the_first_size_that_meets_it_with_95_percent() -> None:
    """Issue 28: the audited RMS meets a target on >= 90 % of robots, so the plan stops
    where the 95th percentile of the audited RMS meets it, not its mean."""
    robot = get_robot("puma560")
    full = plan_poses(robot, 40, candidates=1000)
    target = float(full.rms_by_size_cm[29])
    short = plan_poses(robot, 80, target_rms_cm=target, candidates=1000)
    n = len(short.q)
    assert (
        n > 30 and short.rms_q95_cm <= target < plan_poses(robot, n - 1, candidates=1000).rms_q95_cm
    )
    np.testing.assert_allclose(short.q[:30], full.q[:30])  # the same greedy, stopped later


def test_simulate_records_exactly_the_plan_and_identifies_it(tmp_path, puma_plan) -> None:
    robot = get_robot("puma560")
    f = write_plan(tmp_path / "plan.csv", robot, puma_plan)
    assert np.allclose(read_pose_plan(f, robot), puma_plan.q, atol=1e-6)
    with pytest.raises(ArmsigError, match="already exists"):
        write_plan(f, robot, puma_plan)
    d = tmp_path / "s"
    opts = SimulationOptions(sensor="tracker", sweeps=False, plan_file=str(f), noiseless=True)
    simulate_session(d, opts)
    identify(d, report=False)
    _, q = sweep_readings(read_table(stage_path(d, "joints")), POSES_SWEEP, 6, robot.prismatic)
    assert np.allclose(q, puma_plan.q, atol=1e-6)
    assert audit(d, configurations=200).signature.max_position_cm <= 1e-6


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("step,a,b\n0,1,2\n", "columns do not match"),
        ("step,waist_deg,shoulder_deg,elbow_deg,wrist_roll_deg,wrist_bend_deg,flange_deg\n"
         "0,0,0,0,0,400,0\n", "wrist_bend outside its limits"),
        ("step,waist_deg,shoulder_deg,elbow_deg,wrist_roll_deg,wrist_bend_deg,flange_deg\n"
         "1,0,0,0,0,0,0\n", "steps are not 0, 1, 2"),
        ("step,waist_deg,shoulder_deg,elbow_deg,wrist_roll_deg,wrist_bend_deg,flange_deg\n"
         "0,0,x,0,0,0,0\n", "not a number"),
    ],
)  # fmt: skip
def test_a_plan_file_that_does_not_fit_the_robot_is_refused(tmp_path, text, match) -> None:
    f = tmp_path / "plan.csv"
    f.write_text(text)
    with pytest.raises(ArmsigError, match=match):
        read_pose_plan(f, get_robot("puma560"))


def test_plan_and_poses_together_are_refused(tmp_path) -> None:
    opts = SimulationOptions(sensor="tracker", poses=5, plan_file=str(tmp_path / "p.csv"))
    with pytest.raises(ArmsigError, match="--plan and --poses"):
        simulate_session(tmp_path / "s", opts)


def test_plan_from_a_session_picks_its_most_informative_poses(tmp_path) -> None:
    """Issue 28 item 3: `plan --from SESSION` chooses among the session's own poses (their
    recorded noise, its signature's Jacobian); the file holds their readings."""
    from typer.testing import CliRunner

    from pipeline.cli import app
    from pipeline.planning import plan_from_session

    d = tmp_path / "s"
    simulate_session(d, SimulationOptions(sensor="tracker", poses=120, sweeps=False, seed=4))
    identify(d, report=False)
    robot, plan = plan_from_session(d, 30)
    steps = np.array(plan.source_steps)
    assert len(set(steps.tolist())) == 30 and steps.max() < 120
    assert plan.rms_cm < plan.random_rms_cm
    recorded = sweep_readings(read_table(stage_path(d, "joints")), POSES_SWEEP, 6,
                              robot.prismatic)[1]  # fmt: skip
    np.testing.assert_allclose(plan.q, recorded[steps], atol=1e-12)
    out = tmp_path / "again.csv"
    r = CliRunner().invoke(app, ["plan", str(out), "--from", str(d), "--poses", "30"])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(read_pose_plan(out, robot), plan.q, atol=5e-7)
    with pytest.raises(ArmsigError, match="more poses asked than the session holds"):
        plan_from_session(d, 121)
    r = CliRunner().invoke(app, ["plan", str(out), "--from", str(d), "--robot", "puma560"])
    assert r.exit_code != 0 and "one of --robot and --from" in r.output
    # Issue 44: a session whose recording was replaced is stale, refused as `export` does.
    other = tmp_path / "other"
    simulate_session(other, SimulationOptions(sensor="tracker", poses=120, sweeps=False, seed=5))
    (d / "recording.mcap").write_bytes((other / "recording.mcap").read_bytes())
    r = CliRunner().invoke(
        app, ["plan", str(tmp_path / "stale.csv"), "--from", str(d), "--poses", "30"]
    )
    assert r.exit_code == 1 and "identified from another recording.mcap" in r.output, r.output
    assert not (tmp_path / "stale.csv").exists()


@pytest.mark.parametrize(
    ("option", "value"),
    [("--sigma-mm", v) for v in ("0", "nan", "1e-12", "-1", "inf", "1e9")]
    + [("--target-rms-mm", v) for v in ("nan", "inf", "0", "-0.1")]
    + [("--center-sigma-mm", v) for v in ("nan", "0")]
    + [("--plane-sigma-deg", "inf")],
)
def test_plan_numbers_out_of_range_are_one_line(tmp_path, option: str, value: str) -> None:
    """Issue 44: nan died in a LinAlgError (exit 70); 0 took the sensor's law and 1e-12,
    -1, inf and a target of nan or inf wrote a plan without a word."""
    from typer.testing import CliRunner

    from pipeline.cli import EXIT_REFUSED, app

    sweeps = ["--sweeps"] if option in ("--center-sigma-mm", "--plane-sigma-deg") else []
    out = tmp_path / "plan.csv"
    argv = ["plan", str(out), "--robot", "puma560", *sweeps, option, value]
    r = CliRunner().invoke(app, argv)
    assert r.exit_code == EXIT_REFUSED and r.stderr.count("\n") == 1, r.output
    assert r.stderr.startswith(f"error: {option} must be a finite number") and "try:" in r.stderr
    assert f"got {float(value):g}" in r.stderr and not out.exists()
    if not sweeps:  # the function too
        sigma = option == "--sigma-mm"
        with pytest.raises(ArmsigError, match="must be a finite number"):
            plan_poses(get_robot("puma560"), 5, None if sigma else float(value) / 10,
                       float(value) / 10 if sigma else None, candidates=10)  # fmt: skip


def test_a_centre_sigma_no_sweep_can_reach_is_planned_at_the_cap_with_a_warning(tmp_path) -> None:
    """Issue 44: ``--center-sigma-mm 1e-300`` overflowed (exit 70); now every sweep takes the
    1,000 points a sweep is capped at, and a warning says the σ is not met."""
    from typer.testing import CliRunner

    from pipeline.cli import app

    out = tmp_path / "plan.csv"
    argv = ["plan", str(out), "--robot", "puma560", "--sweeps", "--center-sigma-mm", "1e-300"]
    r = CliRunner().invoke(app, argv)
    assert r.exit_code == 0, r.output
    assert "warning: the wanted plane / center σ is not met by sweep 6 flange" in r.stderr
    assert "at 1000 points per sweep" in r.stderr and out.is_file()
