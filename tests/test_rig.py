"""The rig simulator: recordings a real rig could have written, truth kept apart."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from pipeline.kinematics.chain import SerialChain
from pipeline.rig.plan import target_positions, tool_positions
from pipeline.rig.recorder import CHANNELS
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.schemas import mcap_json_schema
from pipeline.units import joints_to_internal

SMALL = {"points": 12, "repeats": 2}


def _read(path: Path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {t: [] for t in CHANNELS}
    with path.open("rb") as fh:
        reader = make_reader(fh)
        for schema, channel, message in reader.iter_messages():
            assert schema is not None and schema.encoding == "jsonschema"
            assert channel.message_encoding == "json"
            out[channel.topic].append(json.loads(message.data))
    return out


def _trilaterate(s_abc: np.ndarray, mics: np.ndarray) -> np.ndarray:
    """Test-local exact trilateration: sphere intersection, z > 0 (in front of the wall)."""
    a, b, c = mics[:3]
    ex = (b - c) / np.linalg.norm(b - c)  # here: the sensor Y axis
    i = ex @ (a - c)
    ey = (a - c - i * ex) / np.linalg.norm(a - c - i * ex)
    ez = np.cross(ex, ey)
    d = np.linalg.norm(b - c)
    j = ey @ (a - c)
    r_c, r_b, r_a = s_abc[..., 2], s_abc[..., 1], s_abc[..., 0]
    u = (r_c**2 - r_b**2 + d**2) / (2 * d)
    v = (r_c**2 - r_a**2 + i**2 + j**2) / (2 * j) - i / j * u
    w = np.sqrt(np.maximum(r_c**2 - u**2 - v**2, 0.0))
    p = c + u[..., None] * ex + v[..., None] * ey
    sign = np.sign(ez[2]) if ez[2] != 0 else 1.0
    return p + sign * w[..., None] * ez


@pytest.fixture(scope="module")
def noiseless(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("noiseless")
    simulate_session(d, SimulationOptions(seed=3, noiseless=True, **SMALL))
    return d


def test_noiseless_ranges_triangulate_to_truth(noiseless: Path) -> None:
    rec = _read(noiseless / "recording.mcap")
    truth = json.loads((noiseless / "rig-truth.json").read_text())
    mics = np.array([rec["/rig/description"][0]["microphones_cm"][m] for m in "ABCD"])
    tp = truth["target_positions_cm"]
    keys = list(zip(tp["sweep"], tp["step"], strict=True))
    p_true = dict(zip(keys, np.array(tp["p"]), strict=True))
    worst = 0.0
    for msg in rec["/sonic/ranges"]:
        s = np.array(msg["ranges_cm"][4][:3], float)
        p = _trilaterate(s, mics)
        worst = max(worst, float(np.linalg.norm(p - p_true[(msg["sweep"], msg["step"])])))
    assert worst < 1e-6, worst


def test_truth_kinematics_reproduce_target_positions(noiseless: Path) -> None:
    truth = json.loads((noiseless / "rig-truth.json").read_text())
    rec = _read(noiseless / "recording.mcap")
    tk = truth["true_kinematics"]
    pris = np.array([t == "prismatic" for t in tk["joint_types"]])
    chain = SerialChain(links=np.array(tk["links"]), prismatic=pris, base=np.array(tk["base"]))
    p_true = np.array(truth["target_positions_cm"]["p"])
    for k, js in enumerate(rec["/robot/joint_state"]):
        q = joints_to_internal(np.array(js["q_encoder"]), pris)
        if js["sweep"] == "tool":
            p = tool_positions(chain, np.eye(4), q, np.array(truth["true_tool_in_last_link_cm"]))
        else:
            local = np.array(truth["true_targets_local_cm"][str(js["sweep"])])
            p = target_positions(chain, np.eye(4), q, js["sweep"], local)
        np.testing.assert_allclose(p, p_true[k], atol=1e-9)


def test_messages_validate_against_schemas(tmp_path: Path) -> None:
    simulate_session(tmp_path, SimulationOptions(seed=1, faults=("dropouts",), **SMALL))
    rec = _read(tmp_path / "recording.mcap")
    for topic, schema_name in CHANNELS.items():
        assert rec[topic], f"no messages on {topic}"
        validator = jsonschema.Draft202012Validator(mcap_json_schema(schema_name))
        for msg in rec[topic]:
            validator.validate(msg)
    assert len(rec["/rig/description"]) == 1 and len(rec["/robot/description"]) == 1
    n_cfg = 6 * SMALL["points"] + 1
    assert len(rec["/robot/joint_state"]) == n_cfg
    assert len(rec["/sonic/ranges"]) == n_cfg * SMALL["repeats"]
    order = [m["sweep"] for m in rec["/robot/joint_state"]]
    assert order[0] == 6 and order[-2] == 1 and order[-1] == "tool"  # Figure 6-7
    # Ground truth never enters the recording.
    text = json.dumps(rec)
    assert "true_kinematics" not in text and "eps_math" not in text and "atmosphere" not in text


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    for sub in ("a", "b"):
        simulate_session(tmp_path / sub, SimulationOptions(seed=5, **SMALL))
    assert (tmp_path / "a/recording.mcap").read_bytes() == (
        tmp_path / "b/recording.mcap"
    ).read_bytes()
    simulate_session(tmp_path / "c", SimulationOptions(seed=6, **SMALL))
    assert (tmp_path / "a/recording.mcap").read_bytes() != (
        tmp_path / "c/recording.mcap"
    ).read_bytes()


def _ranges(path: Path) -> np.ndarray:
    rec = _read(path / "recording.mcap")
    return np.array(
        [
            [[np.nan if v is None else v for v in row] for row in m["ranges_cm"]]
            for m in rec["/sonic/ranges"]
        ]
    )


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("clean")
    simulate_session(d, SimulationOptions(seed=2, **SMALL))
    return d


@pytest.mark.parametrize("fault", ["bias", "dropouts", "outliers", "wac"])
def test_each_fault_changes_the_recording_as_documented(
    tmp_path: Path, clean: Path, fault: str
) -> None:
    opts = (
        SimulationOptions(seed=2, wac_error_cm=1.0, **SMALL)
        if fault == "wac"
        else SimulationOptions(seed=2, faults=(fault,), **SMALL)
    )
    simulate_session(tmp_path, opts)
    base, hit = _ranges(clean), _ranges(tmp_path)
    if fault == "wac":
        a0 = np.array(_read(clean / "recording.mcap")["/rig/description"][0]["microphones_cm"]["A"])
        a1 = np.array(
            _read(tmp_path / "recording.mcap")["/rig/description"][0]["microphones_cm"]["A"]
        )
        assert abs(np.linalg.norm(a1) - np.linalg.norm(a0) - 1.0) < 1e-9
        np.testing.assert_array_equal(np.isnan(base), np.isnan(hit))
        return
    both = ~np.isnan(base) & ~np.isnan(hit)
    diff = np.where(both, hit - base, 0.0)
    if fault == "dropouts":
        assert np.isnan(hit).sum() > np.isnan(base).sum()
    elif fault == "outliers":
        assert np.sum(np.abs(diff) >= 4.9) > 0
    else:  # bias: every range of a microphone shifts by its bias, up to quantization
        per_mic = np.array([np.median(diff[..., m][both[..., m]]) for m in range(4)])
        bias = json.loads((tmp_path / "rig-truth.json").read_text())["sensor"]["mic_bias_cm"]
        assert np.all(np.abs(per_mic) > 0)
        # the same noise as the clean session of the seed: each range differs by its
        # microphone's bias up to the two roundings to 0.01 cm (before: the bias draw
        # consumed the noise stream, ~0.1 cm apart)
        off = np.abs(diff - np.asarray(bias)) * both
        assert off.max() <= 0.01 + 1e-9
        assert np.sum(np.abs(diff) >= 4.9) == 0


def test_stanford_session(tmp_path: Path) -> None:
    simulate_session(tmp_path, SimulationOptions(robot="stanford", seed=1, **SMALL))
    rec = _read(tmp_path / "recording.mcap")
    desc = rec["/robot/description"][0]
    assert [j["type"] for j in desc["robot"]["joints"]][2] == "prismatic"
    js = [m for m in rec["/robot/joint_state"] if m["sweep"] == 3]
    assert js[0]["units"][2] == "cm" and js[-1]["q_encoder"][2] > js[0]["q_encoder"][2]


def test_default_session_is_small_and_has_no_missing_target_echoes(tmp_path: Path) -> None:
    simulate_session(tmp_path, SimulationOptions(seed=7))
    assert (tmp_path / "recording.mcap").stat().st_size < 3e6
    r = _ranges(tmp_path)
    assert r.shape == ((6 * 100 + 1) * 10, 5, 4)
    assert not np.isnan(r[:, 4, :3]).any()  # target always heard by A, B, C
    assert not np.isnan(r[:, :4, :]).all(axis=0).any()  # every rod/mic pair heard at least once


def test_bad_options() -> None:
    from pipeline.errors import ArmsigError

    with pytest.raises(ArmsigError, match="unknown fault"):
        simulate_session("/nonexistent", SimulationOptions(faults=("smoke",)))
    with pytest.raises(ArmsigError, match="too few"):
        simulate_session("/nonexistent", SimulationOptions(points=2))


def test_candidate_search_in_blocks_gives_the_same_plan(monkeypatch) -> None:
    """The planner searches long joint travels in blocks of candidates (12 joints of
    ±720° peaked at 2.4 GB in one block, now 0.64 GB); any block size gives the same plan."""
    import pipeline.rig.plan as plan
    from pipeline.robots import get_robot
    from pipeline.sensor.geometry import default_geometry

    robot = get_robot("puma560")
    args = (robot, default_geometry(), plan.default_sensor_from_base(robot), 12, 1)
    whole = plan.plan_measurements(*args).to_dict()
    monkeypatch.setattr(plan, "_SEARCH_BYTES", 1 << 20)  # a few candidates a block, not 400
    assert plan.plan_measurements(*args).to_dict() == whole
