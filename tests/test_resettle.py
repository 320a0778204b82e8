"""Held joints that re-settle between sweeps (issue 14): the simulator and the frames fix."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from pipeline.identify import identify
from pipeline.kinematics.signature import frames_at_signature
from pipeline.rig.audit import audit
from pipeline.rig.resettle import resettle
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.robots import get_robot
from pipeline.stages.runner import stage_path

EXACT = {"noiseless": True, "points": 12, "repeats": 1}


def test_resettle_moves_held_joints_between_sweeps_only() -> None:
    sweeps = [3, 3, 3, 2, 2, 1, 1, 1, "tool"]
    q = np.tile([10.0, 20.0, 30.0], (len(sweeps), 1))
    res = np.array([0.01, 0.02, 0.5])
    out = resettle(q, sweeps, res, 2, np.random.default_rng(0))
    counts = (out - q) / res
    assert np.allclose(counts, np.round(counts), atol=1e-9)
    counts = np.round(counts)
    assert not counts[:3].any()  # the first sweep starts at the commanded q^s
    blocks = [slice(0, 3), slice(3, 5), slice(5, 8), slice(8, 9)]
    for b in blocks:  # constant within a sweep
        assert (counts[b] == counts[b][:1]).all()
    held = {3: [0, 1], 2: [0, 2], 1: [1, 2], "tool": [0, 1, 2]}
    for prev, cur in zip(blocks[:-1], blocks[1:], strict=True):
        sweep = sweeps[cur.start]
        was_swept = int(sweeps[prev.start]) - 1
        for j in held[sweep]:
            before = 0.0 if j == was_swept else counts[prev.start, j]
            assert 1 <= abs(counts[cur.start, j] - before) <= 2, (sweep, j)
    assert np.array_equal(resettle(q, sweeps, res, 0, np.random.default_rng(0)), q)


def test_simulated_recording_shows_resettling(tmp_path: Path) -> None:
    simulate_session(tmp_path, SimulationOptions(seed=3, resettle_counts=2, **EXACT))
    identify(tmp_path, only="joints")
    joints = pl.read_ipc(stage_path(tmp_path, "joints"))
    res = get_robot("puma560").encoder_resolution
    per_sweep = joints.group_by("sweep", "joint").agg(pl.col("q_deg").n_unique().alias("k"))
    for row in per_sweep.iter_rows(named=True):  # held joints hold still within a sweep
        assert row["k"] == 1 or row["joint"] == row["sweep"], row
    j1 = joints.filter(pl.col("joint") == 1).group_by("sweep").agg(pl.col("q_deg").first())
    q1 = dict(j1.iter_rows())
    steps = np.diff([q1[s] for s in (6, 5, 4, 3, 2)]) / res[0]
    assert np.allclose(steps, np.round(steps), atol=1e-6)  # whole counts, read by the encoder
    assert (np.abs(np.round(steps)) >= 1).all()


@pytest.mark.parametrize("robot", ["puma560", "stanford"])
def test_noiseless_session_with_resettling_is_exact(tmp_path: Path, robot: str) -> None:
    # Before the frames fix: 0.018 cm RMS (puma560, seed 5), 0.027 cm (stanford).
    simulate_session(tmp_path, SimulationOptions(robot=robot, seed=5, resettle_counts=2, **EXACT))
    identify(tmp_path, report=False)
    r = audit(tmp_path, configurations=300)
    assert r.signature.max_position_cm <= 1e-6, r.signature
    assert r.signature.max_orientation_deg <= 1e-7, r.signature


def test_tracker_session_with_resettling_and_checks_is_exact(tmp_path: Path) -> None:
    opts = SimulationOptions(sensor="tracker", seed=4, noiseless=True, points=8,
                             resettle_counts=2, check=5)  # fmt: skip
    simulate_session(tmp_path, opts)
    identify(tmp_path, report=False)
    assert audit(tmp_path, configurations=200).signature.max_position_cm <= 1e-6


def test_frames_without_resettling_are_unchanged() -> None:
    rng = np.random.default_rng(1)
    F = np.tile(np.eye(4), (4, 1, 1))
    F[:, :3, 3] = rng.normal(0, 30, (4, 3))
    qs = rng.normal(0, 1, 4)
    out = frames_at_signature(F, np.tile(qs, (4, 1)), qs, np.zeros(4, bool))
    assert np.array_equal(out, F)  # bit for bit: today's sessions keep their signatures


def test_cli_resettle_option_and_truth(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from pipeline.cli import app

    args = ["simulate", "--noiseless", "--points", "3", "--repeats", "1"]
    r = CliRunner().invoke(app, [*args, str(tmp_path / "a"), "--resettle-counts", "1"])
    assert r.exit_code == 0, r.output
    truth = json.loads((tmp_path / "a" / "rig-truth.json").read_text())
    assert truth["options"]["resettle_counts"] == 1
    r = CliRunner().invoke(app, [*args, str(tmp_path / "b")])
    assert r.exit_code == 0, r.output
    # Off by default, and then absent from rig-truth.json: today's files keep their bytes.
    assert "resettle_counts" not in json.loads((tmp_path / "b" / "rig-truth.json").read_text())
    r = CliRunner().invoke(app, [*args, str(tmp_path / "c"), "--resettle-counts", "-1"])
    assert r.exit_code == 2
