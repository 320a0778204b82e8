"""The joint refinement (issue 15): exact on noiseless sessions, better than the thesis on
noisy ones, the thesis's tables byte for byte when disabled, one-line errors on bad input,
and a covariance that predicts the spread of the estimates."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from recording_data import small_session

from pipeline.errors import ArmsigError
from pipeline.identify import identify
from pipeline.refine.kinematics import ChainModel
from pipeline.refine.solve import Problem, refit, solve
from pipeline.rig.audit import audit
from pipeline.schemas import validate_table
from pipeline.stages.refine import refine_summary
from pipeline.stages.refine_problem import point_block
from pipeline.stages.runner import run, stage_path
from pipeline.stages.tables import content_hash, read_table

OFF = {"refine": {"enabled": False}}


def _identified(factory, **options) -> Path:
    d = small_session(factory, **options)
    if not (d / "signature.json").is_file():
        identify(d, report=False)
    return d


def _verdict(d: Path) -> str:
    line = read_table(stage_path(d, "verdict")).column("line")[0].as_py()
    return line if not line.startswith("PASS") else "PASS"


def _summary(d: Path) -> dict:
    return refine_summary(read_table(stage_path(d, "refine")))


@pytest.mark.parametrize("robot", ["puma560", "stanford", "scara"])
def test_noiseless_tracker_sessions_refine_exactly(tmp_path_factory, robot: str) -> None:
    d = _identified(
        tmp_path_factory, sensor="tracker", seed=1, noiseless=True, points=5, robot=robot
    )
    assert _summary(d)["status"] == "converged"
    assert json.loads((d / "signature.json").read_text())["model"] == "refined"
    assert audit(d, configurations=200).signature.max_position_cm <= 1e-6
    assert _verdict(d) == "PASS"  # issue 33: CHECK before the verdict's floor


@pytest.mark.parametrize(
    ("robot", "level"),
    [("puma560", "ranges"), ("puma560", "points"), ("stanford", "ranges"), ("scara", "ranges")],
)
def test_noiseless_sonic_session_refines_exactly(
    tmp_path_factory, tmp_path, robot: str, level: str
) -> None:
    d = tmp_path / "s"
    shutil.copytree(small_session(tmp_path_factory, seed=3, noiseless=True, robot=robot), d)
    run(d, overrides={"refine": {"level": level}})
    assert _summary(d)["level"] == level and _summary(d)["status"] == "converged"
    assert audit(d, configurations=200).signature.max_position_cm <= 1e-6
    assert _verdict(d) == "PASS"  # issue 33: CHECK before the verdict's floor


def test_noiseless_session_in_drifting_air_identifies_exactly_and_passes(
    tmp_path_factory,
) -> None:
    """Issue 33: a speed of sound exactly linear in height (Appendix E's model) drifting
    with periods of 8, 18 and 45 minutes. Before: the 120 s speed spline could not follow
    it (2.8e-4 cm on this session; CHECK). The knots chosen from the rods: 6.6e-9 cm."""
    d = _identified(tmp_path_factory, seed=3, noiseless=True, air="drifting")
    summary = _summary(d)
    assert summary["status"] == "converged" and summary["speed_knot_spacing_s"] <= 15.0
    assert audit(d, configurations=200).signature.max_position_cm <= 1e-6
    verdict = json.loads((d / "signature.json").read_text())["refinement"]["verdict"]
    assert verdict["verdict"] == "PASS", verdict["line"]


def _thesis_and_refined(d: Path) -> tuple[float, float]:
    run(d, overrides=OFF)
    thesis = audit(d, configurations=500).signature.rms_position_cm
    run(d)
    return thesis, audit(d, configurations=500).signature.rms_position_cm


def test_refined_beats_the_thesis_on_a_noisy_tracker_session(tmp_path_factory, tmp_path) -> None:
    d = tmp_path / "s"
    shutil.copytree(small_session(tmp_path_factory, sensor="tracker", seed=7, points=20), d)
    thesis, refined = _thesis_and_refined(d)
    assert refined < thesis


def test_refined_beats_the_thesis_on_a_robot3_like_sonic_session(tmp_path) -> None:
    """robot3's recording (seed 3, default plan and noise), both levels: 0.0093 cm
    (thesis) -> 0.0083 cm (points), 0.0051 cm (ranges, the sonic default)."""
    src = Path(__file__).parents[1] / "sessions" / "robot3"
    if not (src / "recording.mcap").is_file():
        pytest.skip("sessions/robot3 is not checked out")
    d = tmp_path / "robot3"
    d.mkdir()
    for name in ("recording.mcap", "rig-truth.json"):
        shutil.copy(src / name, d / name)
    thesis, refined = _thesis_and_refined(d)
    assert _summary(d)["level"] == "ranges"
    assert 0.5 < _summary(d)["noise_scale"] ** 2 < 2.0  # chi2/dof: the range noise (7.9) holds
    assert refined < 0.6 * thesis
    run(d, overrides={"refine": {"level": "points"}})
    assert refined < audit(d, configurations=500).signature.rms_position_cm < thesis


def test_disabled_gives_the_thesis_tables_byte_for_byte(tmp_path_factory, tmp_path) -> None:
    from pipeline.stages import dh, smodel

    d = tmp_path / "s"
    shutil.copytree(small_session(tmp_path_factory, seed=4), d)
    run(d, overrides=OFF)
    t = {n: read_table(stage_path(d, n)) for n in ("session", "frames", "chain", "refine")}
    assert t["refine"].num_rows == 0 and refine_summary(t["refine"])["enabled"] is False
    assert content_hash(t["chain"]) == content_hash(t["frames"])
    today = {"frames": t["frames"], "session": t["session"]}  # the stages as they read before
    for stage in (smodel, dh):
        old = stage.compute({**today, "chain": t["frames"]}, stage.STAGE.params)
        old = validate_table(old, stage.STAGE.name)
        assert content_hash(read_table(stage_path(d, stage.STAGE.name))) == content_hash(old)
    doc = json.loads((d / "signature.json").read_text())
    assert doc["model"] == "smodel" and doc["smodel"] == doc["thesis_smodel"]
    run(d)  # enabled again: a different chain, the thesis kept beside it
    doc = json.loads((d / "signature.json").read_text())
    assert doc["model"] == "refined" and doc["smodel"] != doc["thesis_smodel"]
    assert doc["refinement"]["status"] == "converged"


def test_a_sweep_without_usable_positions_is_one_line(tmp_path_factory, tmp_path) -> None:
    """All positions of a sweep null (a corrupted input): refused with one line, not a
    traceback or a silently wrong chain."""
    from pipeline.stages.refine_problem import session_problem

    d = _identified(tmp_path_factory, sensor="tracker", seed=1, noiseless=True, points=5)
    t = {n: read_table(stage_path(d, n)) for n in ("session", "joints", "positions", "frames")}
    pos = t["positions"]
    sweep = pos.column("sweep").to_numpy()
    for c in ("x_cm", "y_cm", "z_cm"):
        v = pos.column(c).to_numpy(zero_copy_only=False).astype(float)
        v[sweep == 3] = np.nan
        pos = pos.set_column(pos.schema.get_field_index(c), c, pa.array(v, mask=np.isnan(v)))
    with pytest.raises(ArmsigError) as err:
        session_problem({**t, "positions": pos})
    assert "sweep 3 has 0 usable positions" in str(err.value) and "\n" not in str(err.value)


def test_check_rows_are_held_out(tmp_path_factory) -> None:
    d = _identified(tmp_path_factory, sensor="tracker", seed=1, noiseless=True, points=5, check=4)
    block = point_block(read_table(stage_path(d, "positions")))
    sweeps = set(block.keys.column("sweep").to_pylist())
    assert -1 not in sweeps and 0 in sweeps


def _toy(rng: np.random.Generator, sigma: float) -> tuple[Problem, np.ndarray, np.ndarray]:
    """One revolute joint about z, one target on it at 12 angles, noise ``sigma`` (cm)."""
    theta = np.linspace(0.0, 2.0, 12)[:, None]
    model = ChainModel(
        frames0=np.eye(4)[None], prismatic=np.array([False]), link=np.ones(12, np.int64),
        theta=theta, point=np.zeros(12, np.int64), point_names=("sweep1/T",),
    )  # fmt: skip
    x_true = np.array([0.001, -0.002, 0.05, -0.03, 20.0, 1.0, 5.0])
    p = model.positions(x_true) + rng.normal(0.0, sigma, (12, 3))
    keys = pa.table(
        {"sweep": pa.array([1] * 12, pa.int32()), "step": pa.array(range(12), pa.int32())}
    ).append_column("target", pa.array(["T"] * 12))
    from pipeline.refine.points import PointBlock

    # stated σ twice the true one: the reported σ holds only through the χ²/dof scaling
    block = PointBlock(keys, p, np.tile(np.eye(3) / (2.0 * sigma), (12, 1, 1)))
    x0 = x_true.copy()
    x0[:4] = 0.0
    return Problem(model, block, loss="linear"), x0, x_true


def test_reported_sigma_matches_the_spread_over_seeds() -> None:
    """Over 40 seeds of a small noisy problem the reported σ of each parameter is within
    30 % of the spread of its estimates."""
    est, sig = [], []
    for seed in range(40):
        problem, x0, _ = _toy(np.random.default_rng(seed), 0.01)
        sol = solve(problem, x0)
        est.append(sol.x)
        sig.append(sol.sigma)
    spread = np.std(est, axis=0, ddof=1)
    ratio = np.median(sig, axis=0) / spread
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio


def test_refit_leaves_out_the_masked_positions() -> None:
    problem, x0, _ = _toy(np.random.default_rng(1), 0.01)
    full = solve(problem, x0)
    keep = np.ones(12, bool)
    keep[[2, 7]] = False
    part = refit(problem, keep, full.x)
    assert part.n_residuals == 30 and full.n_residuals == 36
    bad = dataclasses.replace(problem.block, measured=problem.block.measured.copy())
    bad.measured[2] += 50.0  # an outlier in a left-out position changes nothing
    assert np.allclose(refit(dataclasses.replace(problem, block=bad), keep, full.x).x, part.x)
