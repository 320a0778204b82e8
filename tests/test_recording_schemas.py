"""The schemas are the contract: every message is validated, with bounds (issue 13)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import fastjsonschema
import pytest
from recording_data import read_raw, small_session, write_raw

from pipeline.contract.batch_schema import all_valid
from pipeline.errors import RecordingError
from pipeline.schemas import mcap_json_schema, schema_dir
from pipeline.stages.recording import read_recording


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    return small_session(tmp_path_factory)


def _set(path: tuple, value: Any):
    def edit(m: dict) -> None:
        node = m
        for key in path[:-1]:
            node = node[key]
        if value is _DELETE:
            del node[path[-1]]
        else:
            node[path[-1]] = value

    return edit


_DELETE = object()

# (topic, edit, what the error names)
RANGES = "/sonic/ranges"
JOINTS = "/robot/joint_state"
RIG = "/rig/description"
ROBOT = "/robot/description"
CASES = {
    "range_negative": (RANGES, _set(("ranges_cm", 4, 0), -3.0), "bigger than 0"),
    "range_zero": (RANGES, _set(("ranges_cm", 4, 0), 0), "bigger than 0"),
    "range_huge": (RANGES, _set(("ranges_cm", 4, 0), 1e300), "smaller than or equal"),
    "range_string": (RANGES, _set(("ranges_cm", 4, 0), "100.0"), "number or null"),
    "range_bool": (RANGES, _set(("ranges_cm", 4, 0), True), "number or null"),
    "range_below_window": (RANGES, _set(("ranges_cm", 4, 0), 12.5), "outside the digitizer"),
    "range_above_window": (RANGES, _set(("ranges_cm", 4, 0), 251.0), "outside the digitizer"),
    "ranges_3_columns": (RANGES, _set(("ranges_cm", 2), [1.0, 2.0, 3.0]), "ranges_cm"),
    "sweep_99": (RANGES, _set(("sweep",), 99), "sweep"),
    "sweep_7": (RANGES, _set(("sweep",), 7), "names no planned position"),
    "sweep_word": (RANGES, _set(("sweep",), "tools"), "sweep"),
    "step_negative": (RANGES, _set(("step",), -1), "step"),
    "step_fraction": (RANGES, _set(("step",), 1.5), "step"),
    "step_beyond_plan": (RANGES, _set(("step",), 12), "names no planned position"),
    "repeat_beyond_plan": (RANGES, _set(("repeat",), 5), "beyond the plan"),
    "encoder_string": (JOINTS, _set(("q_encoder", 0), "1"), "q_encoder"),
    "encoder_bool": (JOINTS, _set(("q_encoder", 0), False), "q_encoder"),
    "encoder_outside_limits": (JOINTS, _set(("q_encoder", 1), 400.0), "outside its limits"),
    "encoder_huge": (JOINTS, _set(("q_encoder", 1), 1e300), "q_encoder"),
    "commanded_outside_limits": (JOINTS, _set(("q_commanded", 2), -700.0), "outside its limits"),
    "units_word": (JOINTS, _set(("units", 0), "rad"), "units"),
    "units_wrong_type": (JOINTS, _set(("units", 0), "cm"), "does not fit the robot"),
    "units_short": (JOINTS, _set(("units",), ["deg"]), "does not fit the robot"),
    "encoder_short": (JOINTS, _set(("q_encoder",), [0.0, 1.0]), "does not fit the robot"),
    "speed_zero": (RIG, _set(("nominal_speed_cm_s",), 0), "nominal_speed_cm_s"),
    "speed_negative": (RIG, _set(("nominal_speed_cm_s",), -34000.0), "nominal_speed_cm_s"),
    "speed_implausible": (RIG, _set(("nominal_speed_cm_s",), 3.4e9), "nominal_speed_cm_s"),
    "window_empty": (RIG, _set(("range_min_cm",), 300.0), "range window"),
    "mic_string": (RIG, _set(("microphones_cm", "A", 0), "0"), "microphones_cm"),
    "mode_bogus": (ROBOT, _set(("mode",), "bogus"), "mode"),
    "robot_malformed": (ROBOT, _set(("robot", "joints"), "six"), "joints"),
    "plan_joint_beyond_robot": (ROBOT, _set(("plan", "sweeps", 0, "joint"), 9), "plan"),
    "signature_q_short": (ROBOT, _set(("signature_q",), [0.0]), "signature_q"),
}


def _write_edited(session: Path, dst: Path, topic: str, edit) -> None:
    raw, _ = read_raw(session / "recording.mcap")
    k = next(i for i, m in enumerate(raw) if m.topic == topic)
    payload = raw[k].payload
    edit(payload)
    raw[k] = raw[k].with_payload(payload)
    write_raw(dst / "recording.mcap", raw)


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_message_breaking_the_contract_is_refused(
    session: Path, tmp_path: Path, case: str
) -> None:
    topic, edit, match = CASES[case]
    _write_edited(session, tmp_path, topic, edit)
    with pytest.raises(RecordingError, match=match) as exc:
        read_recording(tmp_path / "recording.mcap")
    assert "\n" not in str(exc.value)


def _required() -> list[tuple[str, str]]:
    topics = {
        "rig_description": RIG,
        "robot_description": ROBOT,
        "joint_state": JOINTS,
        "sonic_ranges": RANGES,
    }
    out = []
    for name, topic in topics.items():
        schema = mcap_json_schema(name)
        # the rig description's sonic fields are required in its "else" (sensor sonic) branch
        fields = schema.get("required", []) + schema.get("else", {}).get("required", [])
        out += [(topic, f) for f in fields]
    return out


@pytest.mark.parametrize(("topic", "field"), _required())
def test_every_required_field_of_the_schema_files_is_checked(
    session: Path, tmp_path: Path, topic: str, field: str
) -> None:
    """Before: 4 of the 7 required /rig/description fields were checked."""
    _write_edited(session, tmp_path, topic, _set((field,), _DELETE))
    with pytest.raises(RecordingError, match=field):
        read_recording(tmp_path / "recording.mcap")


def test_old_mode_word_reads_as_hardware(session: Path, tmp_path: Path) -> None:
    _write_edited(session, tmp_path, ROBOT, _set(("mode",), "real"))
    assert read_recording(tmp_path / "recording.mcap").robot["mode"] == "hardware"


def test_mode_enum_is_the_same_in_every_schema() -> None:
    modes = {
        p.stem: tuple(json.loads(p.read_text())["properties"]["mode"]["enum"])
        for p in (schema_dir() / "mcap").glob("*.json")
        if "mode" in json.loads(p.read_text())["properties"]
    }
    # a session recording may also be converted from a foreign file; an evaluation is not
    assert modes.pop("robot_description") == ("simulated", "hardware", "imported")
    assert set(modes.values()) == {("simulated", "hardware")}, modes


@pytest.mark.parametrize("case", sorted(CASES))
def test_batch_validation_never_accepts_what_the_schema_refuses(session: Path, case: str) -> None:
    """The column-wise check of high-volume channels is at least as strict as the schema."""
    topic, edit, _ = CASES[case]
    names = {
        RIG: "rig_description",
        ROBOT: "robot_description",
        JOINTS: "joint_state",
        RANGES: "sonic_ranges",
    }
    schema = mcap_json_schema(names[topic])
    raw, _ = read_raw(session / "recording.mcap")
    msgs = [m.payload for m in raw if m.topic == topic]
    if topic in (RANGES, JOINTS):  # the channels it serves: valid messages pass
        assert all_valid(schema, msgs)
    bad = copy.deepcopy(msgs)
    edit(bad[len(bad) // 2])
    try:
        fastjsonschema.compile(schema)(bad[len(bad) // 2])
    except fastjsonschema.JsonSchemaValueException:
        assert not all_valid(schema, bad)
