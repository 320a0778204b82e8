"""Sweep plans (issue 28): points per sweep and range per joint from (6.11)-(6.13), the
thesis's example numbers (Section 6.6, Tables 6-1, 6-4 and 6-5; Section 6.4, (6.7)), the
exact arc statistics where the thesis is silent, and ``pipeline plan --sweeps``."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.features.accuracy import (
    MAX_POINTS,
    MIN_POINTS,
    arc_accuracy,
    points_for_accuracy,
    sigma_center,
    sweep_accuracy,
)
from pipeline.features.circle import fit_circle
from pipeline.features.plane import fit_plane_eigen
from pipeline.planning.sweeps import THESIS_RANGES_PER_CYCLE, measurement_count, plan_sweeps
from pipeline.robots import get_robot

# Table 6-4 (normal and radial residual stdev, cm), Table 6-1 (nominal radii, cm) and
# Table 6-5 (σ_δ deg, σ_c cm) of Robot 1, joints 1-6 (Section 6.6).
SIGMA_N = (0.0137, 0.0291, 0.0379, 0.0107, 0.0119, 0.0152)
SIGMA_R = (0.0115, 0.0181, 0.0142, 0.0204, 0.0095, 0.0152)
RADIUS = (40.87, 41.62, 43.71, 33.30, 45.13, 33.30)
TABLE_6_5_DELTA_DEG = (0.002937, 0.007397, 0.008514, 0.003204, 0.004149, 0.003699)
TABLE_6_5_CENTER_CM = (0.00176, 0.00335, 0.00250, 0.00356, 0.00184, 0.00176)


def test_table_6_5_joint_6_plane_is_6_11_with_100_points() -> None:
    """Section 6.6, Table 6-5: joint 6 (a full turn: the Puma's flange turns ±266°) with
    σ_n = .0152 cm (Table 6-4) and R_6 = 33.30 cm (Table 6-1): σ_δ = .003699° is (6.11)
    with n = 100 (the N_i of (6.7)'s example; Table 6-5 does not print it), to the
    table's 4 digits, and "accurate to within ±.0074 deg" is its 2σ. The plan inverts it:
    100 points for that σ_δ."""
    full = 2 * np.pi
    d, _, law = sweep_accuracy(SIGMA_N[5], SIGMA_R[5], RADIUS[5], 100, full)
    assert law == "(6.11)"
    assert round(np.degrees(d), 6) == TABLE_6_5_DELTA_DEG[5]
    assert round(2 * np.degrees(d), 4) == 0.0074
    plane = np.radians(TABLE_6_5_DELTA_DEG[5])
    assert points_for_accuracy(SIGMA_N[5], SIGMA_R[5], RADIUS[5], full, plane) == 100


@pytest.mark.parametrize("j", [0, 1, 2, 3])
def test_table_6_5_joints_1_to_4_are_consistent_with_6_12_and_6_13(j: int) -> None:
    """Table 6-5 does not print joints 1-4's N_i or sweep X. With N_i = 100, the X for
    which (6.12) gives the printed σ_δ (316°, 261°, 281°, 276°: near the Puma's travels)
    makes (6.13) give the printed σ_c within 2.5 %: both fits' constants as the thesis
    used them (joints 5 and 6 follow neither pair: 6's plane is (6.11), a full turn)."""
    s_d = np.radians(TABLE_6_5_DELTA_DEG[j])
    x_deg = (SIGMA_N[j] ** 2 / (RADIUS[j] ** 2 * s_d**2 * 100) + 0.344) / 0.00244  # (6.12)
    assert 250 < x_deg < 320
    assert sweep_accuracy(SIGMA_N[j], SIGMA_R[j], RADIUS[j], 100, np.radians(x_deg))[0] == (
        pytest.approx(s_d, rel=1e-12)
    )
    s_c = sigma_center(SIGMA_R[j], 100, np.radians(x_deg))  # Eq. (6.13)
    assert s_c == pytest.approx(TABLE_6_5_CENTER_CM[j], rel=0.025)


def test_6_7_slant_ranges_of_a_session() -> None:
    """Section 6.4, (6.7): N_i = 100 for six joints and N_avg = 10: 42,000 slant ranges."""
    assert measurement_count((100,) * 6, 10, THESIS_RANGES_PER_CYCLE) == 42_000


@pytest.mark.parametrize("sweep_deg", [120.0, 200.0, 300.0, 360.0])
@pytest.mark.parametrize(("plane_deg", "center_cm"), [(0.004, None), (None, 0.002), (0.004, 0.002)])
def test_points_for_accuracy_is_the_fewest_that_meet_it(sweep_deg, plane_deg, center_cm) -> None:
    x = np.radians(sweep_deg)
    plane = None if plane_deg is None else np.radians(plane_deg)
    n = points_for_accuracy(0.012, 0.015, 40.0, x, plane, center_cm)

    def meets(k: int) -> bool:
        d, c, _ = sweep_accuracy(0.012, 0.015, 40.0, k, x)
        return (plane is None or d <= plane) and (center_cm is None or c <= center_cm)

    if n > MAX_POINTS:  # a short sweep's center: unreachable, and said so
        assert sweep_deg < 180 and not meets(MAX_POINTS)
        return
    assert meets(n) and (n == MIN_POINTS or not meets(n - 1))


def test_the_arc_statistics_agree_with_the_thesis_where_it_speaks() -> None:
    """(6.12)/(6.13) are fits of the exact statistics of an arc (within their 4.4 % and
    ~3 % over 180-360°); a full turn's center is 2σ²/n, (6.11)'s plane 2σ²/(R² n)."""
    for sweep_deg in (180.0, 240.0, 300.0):
        x = np.radians(sweep_deg)
        exact = arc_accuracy(0.01, 0.01, 40.0, 200, x)
        thesis = sweep_accuracy(0.01, 0.01, 40.0, 200, x)
        np.testing.assert_allclose(exact, thesis[:2], rtol=0.05)
    d, c = arc_accuracy(0.01, 0.01, 40.0, 100, 2 * np.pi)
    np.testing.assert_allclose([d, c], [np.sqrt(2e-4 / (1600 * 100)), np.sqrt(2e-4 / 100)])


def test_the_arc_statistics_match_fits_of_noisy_short_sweeps(rng) -> None:
    """Where the thesis is silent (a 90° sweep): the plane's largest tilt σ and the
    center's largest coordinate σ of 2,000 noisy 30-point arcs, fitted by (4.19)-(4.43),
    against :func:`arc_accuracy` (2,000 draws: ~3 % in σ)."""
    n, x, r, s = 30, np.radians(90.0), 40.0, 0.01
    phi = np.linspace(0.0, x, n)
    clean = r * np.stack([np.cos(phi), np.sin(phi), np.zeros(n)], axis=-1)
    pts = clean + rng.normal(scale=s, size=(2000, n, 3))
    plane = fit_plane_eigen(pts)
    circle = fit_circle(pts, plane)
    normal = plane.normal * np.sign(plane.normal[:, 2:3])
    tilt = normal[:, :2]  # small angles about y and x (rad)
    d_exp, c_exp = arc_accuracy(s, s, r, n, x)
    assert np.sqrt(np.linalg.eigvalsh(np.cov(tilt.T))[-1]) == pytest.approx(d_exp, rel=0.08)
    center = circle.center[:, :2]
    assert np.sqrt(np.linalg.eigvalsh(np.cov(center.T))[-1]) == pytest.approx(c_exp, rel=0.08)


@pytest.fixture(scope="module")
def puma_sweeps():
    return plan_sweeps(get_robot("puma560"), "sonic", plane_sigma_deg=0.005, center_sigma_cm=0.002)


def test_a_sweep_plan_meets_the_wanted_feature_accuracy(puma_sweeps) -> None:
    assert [s.joint for s in puma_sweeps.sweeps] == [6, 5, 4, 3, 2, 1]  # Figure 6-7's order
    for s in puma_sweeps.sweeps:
        assert s.plane_sigma_deg <= 0.005 and s.center_sigma_cm <= 0.002, s
        assert s.last - s.first >= 180.0 and s.law == "(6.12)"  # the widest visible sweep
        x = np.radians(s.last - s.first)
        fewer = sweep_accuracy(s.sigma_n_cm, s.sigma_r_cm, s.radius_cm, s.points - 1, x)
        assert np.degrees(fewer[0]) > 0.005 or fewer[1] > 0.002  # one fewer misses
    assert puma_sweeps.unidentified == ()
    assert 0 < puma_sweeps.rms_cm < puma_sweeps.rms_q95_cm


def test_a_sweep_plan_for_a_tool_target_scales_every_sweep() -> None:
    """Every N_i scaled by one factor to the first (to 2 %) whose whole fit meets the
    target with 95 % probability; never fewer than 1/√N scaling asks (the held joints'
    shared reading errors do not average); an unreachable target gets every sweep at the
    most points, still above it (the CLI warns)."""
    robot = get_robot("puma560")
    few = plan_sweeps(robot, "sonic", points=20)
    target = 0.7 * few.rms_q95_cm
    plan = plan_sweeps(robot, "sonic", target_rms_cm=target)
    n = [s.points for s in plan.sweeps]
    assert plan.rms_q95_cm <= target and len(set(n)) == 1
    assert 20 / 0.7**2 <= n[0] <= 1.2 * 20 / 0.7**2 * 1.5
    assert plan_sweeps(robot, "sonic", points=int(n[0] / 1.03)).rms_q95_cm > target
    floor = plan_sweeps(robot, "tracker", target_rms_cm=1e-4)
    assert {s.points for s in floor.sweeps} == {MAX_POINTS} and floor.rms_q95_cm > 1e-4


def test_the_sweep_plan_file_holds_every_position_in_measuring_order(tmp_path, puma_sweeps):
    from typer.testing import CliRunner

    from pipeline.cli import app

    out = tmp_path / "sweeps.csv"
    args = ["plan", str(out), "--robot", "puma560", "--sweeps", "--plane-sigma-deg", "0.005",
            "--center-sigma-mm", "0.02", "--json"]  # fmt: skip
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    rows = [ln.split(",") for ln in out.read_text().splitlines() if not ln.startswith("#")]
    assert rows[0][:3] == ["sweep", "step", "waist_deg"]
    names = [row[0] for row in rows[1:]]
    assert names == [str(s.joint) for s in puma_sweeps.sweeps for _ in range(s.points)] + ["tool"]
    first = puma_sweeps.sweeps[0]
    q = np.array([row[2:] for row in rows[1 : 1 + first.points]], float)
    np.testing.assert_allclose(q[[0, -1], first.joint - 1], [first.first, first.last])
    assert np.ptp(np.delete(q, first.joint - 1, axis=1), axis=0).max() == 0.0  # others held
    r = CliRunner().invoke(app, args)
    assert r.exit_code != 0 and "already exists" in r.output
    for bad, match in (
        (["--points", "20"], "--points is for sweep plans"),
        (["--sweeps", "--poses", "20"], "--sweeps plans joint sweeps, not poses"),
        (
            ["--sweeps", "--plane-sigma-deg", "-1"],
            "--plane-sigma-deg must be a finite number above 0 deg",
        ),
    ):
        r = CliRunner().invoke(app, ["plan", str(tmp_path / "x.csv"), "--robot", "puma560", *bad])
        assert r.exit_code != 0 and match in r.output, r.output
