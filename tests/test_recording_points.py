"""Point-sensor recordings (/points): read by key, every broken key or value refused in one
line naming it; the positions table carries what was recorded."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from recording_data import Raw, read_raw, small_session, write_raw

from pipeline.contract.channels import POINT_CHANNELS
from pipeline.errors import RecordingError
from pipeline.stages import points
from pipeline.stages.base import RECORDING, NoParams
from pipeline.stages.recording import CHECK_SWEEP, TOOL_SWEEP, read_recording

POINTS = "/points"
JOINTS = "/robot/joint_state"
TRACKER = {"sensor": "tracker", "points": 4, "targets": 3, "check": 2}


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    return small_session(tmp_path_factory, seed=4, noiseless=True, **TRACKER)


def _first(raw: list[Raw], topic: str, **key) -> int:
    return next(
        i
        for i, m in enumerate(raw)
        if m.topic == topic and all(m.payload[k] == v for k, v in key.items())
    )


def _edit(raw: list[Raw], i: int, **fields) -> None:
    payload = {**raw[i].payload, **fields}
    raw[i] = raw[i].with_payload({k: v for k, v in payload.items() if v is not None})


def _set_description(raw: list[Raw], edit) -> None:
    i = _first(raw, "/robot/description")
    doc = raw[i].payload
    edit(doc)
    raw[i] = raw[i].with_payload(doc)


CASES = {
    "duplicated_point": ("recorded twice", "(sweep 3, step 2, target T2)"),
    "point_without_joint_state": ("has no /robot/joint_state", "(sweep 3, step 3, target T1)"),
    "joint_state_without_point": ("has no /points point", "(sweep 3, step 2)"),
    "unplanned_step": ("names no planned position", "(sweep 3, step 4)"),
    "unplanned_check_step": ("names no planned position", "(sweep check, step 2)"),
    "unplanned_target": ("does not plan", "(sweep 3, step 2, target T9)"),
    "not_the_tool_target": ("does not plan", "(sweep tool, step 0, target T2)"),
    "sigma_and_cov": ("both sigma_cm and cov_cm2", "(sweep 3, step 2, target T2)"),
    "asymmetric_cov": ("not symmetric", "(sweep 3, step 2, target T2)"),
    "indefinite_cov": ("not positive definite", "(sweep 3, step 2, target T2)"),
    "non_unit_quaternion": ("not a unit quaternion", "(sweep 3, step 2, target T2)"),
    "tiny_sigma": ("sigma_cm is 1e-200 cm, under 1e-07 cm", "(sweep 3, step 2, target T2)"),
    "tiny_cov": ("cov_cm2's smallest σ is 1e-150 cm", "(sweep 3, step 2, target T2)"),
    "sonic_channel": ("channel /sonic/ranges in a recording of sensor 'points'", ""),
    "untold_tool_target": ("does not say which is the tool", "sweep tool"),
    "orientation_sigma_alone": ("orientation_sigma_deg without", "(sweep 3, step 2, target T2)"),
    "not_a_tool_target": ("does not plan", "(sweep tool, step 0, target T3)"),
    "tool_targets_without_the_tool": ("does not hold plan.tool_target", "tool_target T1"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_broken_point_recordings_are_refused_naming_the_key(
    session: Path, tmp_path: Path, case: str
) -> None:
    raw, _ = read_raw(session / "recording.mcap")
    pt = _first(raw, POINTS, sweep=3, step=2, target="T2")
    channels = dict(POINT_CHANNELS)
    if case == "duplicated_point":
        raw.append(raw[pt])
    elif case == "point_without_joint_state":
        del raw[_first(raw, JOINTS, sweep=3, step=3)]
    elif case == "joint_state_without_point":
        raw = [
            m
            for m in raw
            if not (m.topic == POINTS and (m.payload["sweep"], m.payload["step"]) == (3, 2))
        ]
    elif case == "unplanned_step":
        _edit(raw, pt, step=4)
    elif case == "unplanned_check_step":
        _edit(raw, _first(raw, POINTS, sweep="check", step=1), step=2)
    elif case == "unplanned_target":
        _edit(raw, _first(raw, POINTS, sweep=3, step=2, target="T1"), target="T9")
    elif case == "not_the_tool_target":
        _edit(raw, _first(raw, POINTS, sweep="tool"), target="T2")
    elif case == "sigma_and_cov":
        _edit(raw, pt, cov_cm2=np.diag([1e-6] * 3).tolist())
    elif case == "asymmetric_cov":
        _edit(raw, pt, sigma_cm=None, cov_cm2=[[1e-6, 2e-7, 0], [0, 1e-6, 0], [0, 0, 1e-6]])
    elif case == "indefinite_cov":
        _edit(raw, pt, sigma_cm=None, cov_cm2=[[1e-6, 2e-6, 0], [2e-6, 1e-6, 0], [0, 0, 1e-6]])
    elif case == "tiny_sigma":  # issue 44: identify died in a LinAlgError
        _edit(raw, pt, sigma_cm=1e-200)
    elif case == "tiny_cov":
        _edit(raw, pt, sigma_cm=None, cov_cm2=np.diag([1e-300, 1e-6, 1e-6]).tolist())
    elif case == "non_unit_quaternion":
        _edit(raw, pt, orientation_wxyz=[0.9, 0.1, 0.0, 0.0])
    elif case == "orientation_sigma_alone":
        _edit(raw, pt, orientation_sigma_deg=0.01)
    elif case == "not_a_tool_target":  # plan.tool_targets T1, T2: T3 is no target on the tool
        _set_description(raw, lambda d: d["plan"].update(tool_targets=["T1", "T2"]))
        _edit(raw, _first(raw, POINTS, sweep="tool"), target="T3")
    elif case == "tool_targets_without_the_tool":
        _set_description(raw, lambda d: d["plan"].update(tool_targets=["T2", "T3"]))
    elif case == "sonic_channel":
        channels["/sonic/ranges"] = "sonic_ranges"
        ranges = [[None] * 4 for _ in range(5)]
        raw.append(
            Raw(
                "/sonic/ranges",
                raw[pt].log_time,
                json.dumps({"sweep": 3, "step": 2, "repeat": 0, "ranges_cm": ranges}).encode(),
            )
        )
    else:
        _set_description(raw, lambda d: d["plan"].pop("tool_target"))
        tool = _first(raw, POINTS, sweep="tool")
        raw.append(raw[tool].with_payload({**raw[tool].payload, "target": "T2"}))
    write_raw(tmp_path / "recording.mcap", raw, channels=channels)
    what, key = CASES[case]
    with pytest.raises(RecordingError, match=what) as exc:
        read_recording(tmp_path / "recording.mcap")
    assert key in str(exc.value) and "\n" not in str(exc.value)


def test_tool_sweep_measures_the_targets_on_the_tool(session: Path, tmp_path: Path) -> None:
    """``plan.tool_targets``: the tool sweep may measure every target on the last link, the
    tool point among them (issue 29); without it, only ``plan.tool_target``."""
    raw, _ = read_raw(session / "recording.mcap")
    tool = _first(raw, POINTS, sweep="tool")
    raw.append(raw[tool].with_payload({**raw[tool].payload, "target": "T2"}))
    write_raw(tmp_path / "refused.mcap", raw, channels=POINT_CHANNELS)
    with pytest.raises(RecordingError, match="does not plan"):
        read_recording(tmp_path / "refused.mcap")
    _set_description(raw, lambda d: d["plan"].update(tool_targets=["T1", "T2"]))
    write_raw(tmp_path / "recording.mcap", raw, channels=POINT_CHANNELS)
    rec = read_recording(tmp_path / "recording.mcap")
    assert sorted(rec.point_target[rec.point_sweep == TOOL_SWEEP].tolist()) == ["T1", "T2"]


def test_points_are_keyed_sorted_and_carry_their_uncertainty(session: Path, tmp_path: Path) -> None:
    """Messages in reverse order, one covariance and one quaternion: the recording reads the
    same keys in (sweep, step, target) order, check sweep -1, with the recorded values."""
    raw, _ = read_raw(session / "recording.mcap")
    pt = _first(raw, POINTS, sweep=3, step=2, target="T2")
    cov = [[4e-6, 1e-6, 0.0], [1e-6, 4e-6, 0.0], [0.0, 0.0, 9e-6]]
    _edit(raw, pt, sigma_cm=None, cov_cm2=cov, orientation_wxyz=[0.5, 0.5, 0.5, 0.5])
    write_raw(tmp_path / "recording.mcap", raw[:2] + raw[2:][::-1], channels=POINT_CHANNELS)
    rec = read_recording(tmp_path / "recording.mcap")
    keys = list(
        zip(
            rec.point_sweep.tolist(),
            rec.point_step.tolist(),
            rec.point_target.tolist(),
            strict=True,
        )
    )
    assert keys == sorted(keys) and len(set(keys)) == len(keys)
    assert rec.sensor == "points" and rec.ranges_cm.shape == (0, 5, 4)
    assert sorted({s for s, _, _ in keys}) == [CHECK_SWEEP, TOOL_SWEEP, 1, 2, 3, 4, 5, 6]
    assert {t for s, _, t in keys if s in (TOOL_SWEEP, CHECK_SWEEP)} == {"T1"}
    k = keys.index((3, 2, "T2"))
    assert np.isnan(rec.point_sigma_cm[k]) and rec.point_cov_cm2[k].tolist() == cov
    assert rec.point_wxyz[k].tolist() == [0.5, 0.5, 0.5, 0.5]
    assert np.isnan(rec.point_wxyz[k - 1]).all() and np.isfinite(rec.point_sigma_cm[k - 1])
    table = points.compute({RECORDING: rec}, NoParams()).to_pylist()
    row = next(r for r in table if (r["sweep"], r["step"], r["target"]) == (3, 2, "T2"))
    assert (row["sigma_cm"], row["cov_xy_cm2"], row["cov_zz_cm2"]) == (None, 1e-6, 9e-6)
    assert (row["orientation_w"], row["n_samples"], row["n_used"]) == (0.5, 1, 1)
    assert [(r["sweep"], r["step"], r["target"]) for r in table] == keys
