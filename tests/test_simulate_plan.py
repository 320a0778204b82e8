"""``pipeline simulate`` plans a session once per process (issue 15, the refine study's
cost): the plan depends on the robot, recorded geometry, points, repeats and sweep cap,
never on the seed, and caching it leaves every recording byte-identical."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

import pipeline.rig.simulate as simulate
from pipeline.rig.simulate import SimulationOptions, simulate_session

SMALL = {"points": 12, "repeats": 2}
#: sha256 of recording.mcap as made before the plan was cached (main at ae2a052), seed 5;
#: renewed when the recording embeds a changed channel schema (issue 26: the sweep
#: 'poses' of joint_state.json; issue 27: its optional payload_kg; issue 29: plan.tool_targets
#: of robot_description.json; issue 39: sensor 'camera' of rig_description.json; issue 43:
#: robot_id of robot_description.json; issue 42: source_file, source_line and the tracker
#: drift of joint_state.json), its messages unchanged (checked against 0537394,
#: bef8e5b, 23ce14c and 9454d58: every message's topic, log and publish time and bytes equal).
BEFORE = {
    (): "785b5ff71b01d1555a0f730de37661751740523981dcd7d08544050efb37b02e",
    (("noise_factor", 4.6), ("wac_error_cm", 0.5)): (
        "ad0dd420a772ebe3b9679fb40d8431db2c6b42de58dda255c5684f80ee473059"
    ),
}


def test_the_plan_is_made_once_per_process(tmp_path: Path, monkeypatch) -> None:
    calls = []
    real = simulate.plan_measurements

    def counted(*args, **kwargs):
        calls.append(args[3:5])
        return real(*args, **kwargs)

    monkeypatch.setattr(simulate, "plan_measurements", counted)
    simulate._plan_by_content.cache_clear()
    for seed in (5, 6, 7):  # the seed does not enter the plan
        simulate_session(tmp_path / f"s{seed}", SimulationOptions(seed=seed, **SMALL))
    assert calls == [(12, 2)]
    simulate_session(tmp_path / "other", SimulationOptions(seed=5, points=13, repeats=2))
    assert calls == [(12, 2), (13, 2)]


@pytest.mark.parametrize("extra", list(BEFORE))
def test_cached_plan_keeps_recordings_byte_identical(tmp_path: Path, extra) -> None:
    simulate._plan_by_content.cache_clear()
    for run in ("planned", "cached"):  # the second simulate takes the cached plan
        d = tmp_path / run
        simulate_session(d, SimulationOptions(seed=5, **SMALL, **dict(extra)))
        digest = hashlib.sha256((d / "recording.mcap").read_bytes()).hexdigest()
        assert digest == BEFORE[extra], run


def test_a_changed_geometry_or_placement_is_planned_anew(monkeypatch) -> None:
    """Regression: keyed by the robot and W_AC error only, the cache handed a test that
    mirrors the microphones (tests/test_recording_geometry.py) the plan of the unmirrored
    rig, and its targets were lost."""
    from pipeline.rig.plan import default_sensor_from_base
    from pipeline.robots import get_robot
    from pipeline.sensor.geometry import default_geometry

    calls = []
    real = simulate.plan_measurements
    monkeypatch.setattr(
        simulate, "plan_measurements", lambda *a, **k: calls.append(1) or real(*a, **k)
    )
    simulate._plan_by_content.cache_clear()
    robot, g = get_robot("puma560"), default_geometry()
    T = default_sensor_from_base(robot)
    moved = T.copy()
    moved[0, 3] += 1.0
    for geometry, placement in ((g, T), (g, T), (g, moved), (default_geometry(w_ac=70.0), T)):
        simulate.session_plan(robot, geometry, placement, 12, 1, 300.0)
    assert len(calls) == 3
