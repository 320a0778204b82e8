"""Evaluation inputs: channels joined by their keys, never by log time, and a broken ground
truth reported in one line (issue 13).

A copy of robot1 without ``rig-truth.json`` is a hardware session: its committed
``evaluation.mcap`` is used as recorded, never re-recorded by the simulated rig.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from recording_data import read_raw, write_raw

from pipeline.contract.channels import EVAL_CHANNELS
from pipeline.errors import ArmsigError
from pipeline.evaluate import evaluate

ROBOT1 = Path(__file__).resolve().parent.parent / "sessions" / "robot1"


@pytest.fixture(scope="module")
def hardware(tmp_path_factory) -> tuple[Path, dict]:
    sdir = tmp_path_factory.mktemp("evalkeys") / "robot1"
    shutil.copytree(ROBOT1, sdir, ignore=shutil.ignore_patterns("rig-truth.json"))
    r = evaluate(sdir, report=False)
    assert r.recorded == []
    return sdir, r.summary


def _copy(hardware: tuple[Path, dict], tmp_path: Path) -> Path:
    return Path(shutil.copytree(hardware[0], tmp_path / "robot1"))


@pytest.mark.parametrize("topic", ["/eval/teach", "/eval/program", "/eval/measurement"])
def test_reversed_log_times_give_the_same_evaluation(hardware, tmp_path: Path, topic) -> None:
    """Before: reversed /eval/teach or /eval/program was refused as 'recorded for another
    joint program' (teach points taken in log-time order built the wrong workspace)."""
    sdir = _copy(hardware, tmp_path)
    raw, meta = read_raw(sdir / "evaluation.mcap")
    times = [m.log_time for m in raw if m.topic == topic][::-1]
    it = iter(times)
    for m in raw:
        if m.topic == topic:
            m.log_time = next(it)
    write_raw(sdir / "evaluation.mcap", raw, meta, channels=EVAL_CHANNELS)
    r = evaluate(sdir, report=False)
    assert {**r.summary, "session": None} == {**hardware[1], "session": None}


@pytest.mark.parametrize("topic", ["/eval/teach", "/eval/program", "/eval/measurement"])
def test_a_key_recorded_twice_is_refused(hardware, tmp_path: Path, topic) -> None:
    """Before: a repeated teach point left its task silently unscored."""
    sdir = _copy(hardware, tmp_path)
    raw, _ = read_raw(sdir / "evaluation.mcap")
    k = next(i for i, m in enumerate(raw) if m.topic == topic)
    raw.insert(k + 1, raw[k])
    write_raw(sdir / "evaluation.mcap", raw, channels=EVAL_CHANNELS)
    with pytest.raises(ArmsigError, match="is recorded twice"):
        evaluate(sdir, report=False)


@pytest.mark.parametrize(
    "truth",
    ["{not json", "[]", '{"true_kinematics": 1}', "drop:seed", "drop:sensor_from_base"],
)
def test_a_broken_ground_truth_is_one_line_when_the_rig_records(tmp_path: Path, truth) -> None:
    """Before: the simulated rig read rig-truth.json with a bare json.loads and indexing
    (JSONDecodeError, TypeError or KeyError tracebacks)."""
    import json

    sdir = Path(
        shutil.copytree(ROBOT1, tmp_path / "robot1", ignore=shutil.ignore_patterns("evaluat*"))
    )
    path = sdir / "rig-truth.json"
    if truth.startswith("drop:"):
        doc = json.loads(path.read_text())
        del doc[truth[5:]]
        truth = json.dumps(doc)
    path.write_text(truth)
    with pytest.raises(ArmsigError) as err:
        evaluate(sdir, report=False)
    assert "rig-truth.json" in str(err.value) and "\n" not in str(err.value)
