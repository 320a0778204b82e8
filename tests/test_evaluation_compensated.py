"""The compensated controller of ``pipeline evaluate`` (issue 30, item 7): the design
controller driven to the targets ``pipeline compensate`` rewrites, beside design and
signature control; scored from the recording like the others."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.contract.evaluation import read_evaluation
from pipeline.evaluate import evaluate
from pipeline.evaluation.controllers import CompensatedModel, DesignModel, SignatureModel
from pipeline.rig.evaluation import EvaluationRigOptions
from pipeline.rig.recorder import EVAL_CHANNELS, Message, write_recording
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.rig.true_robot import ErrorSigmas
from pipeline.signature.file import load_signature
from pipeline.stages.runner import stage_path
from pipeline.stages.tables import read_table

ROBOT1 = Path(__file__).resolve().parent.parent / "sessions" / "robot1"
EXACT_RIG = EvaluationRigOptions(perfect_servo=True, exact_instruments=True)


def _values(summary: dict, who: str) -> np.ndarray:
    return np.array([i[who] for t in summary["tasks"].values() for i in t["indices"]], float)


@pytest.fixture(scope="module")
def robot1(tmp_path_factory) -> tuple[Path, dict]:
    sdir = tmp_path_factory.mktemp("comp") / "robot1"
    shutil.copytree(ROBOT1, sdir, ignore=shutil.ignore_patterns("evaluat*", ".evaluation*"))
    return sdir, evaluate(sdir, report=True).summary


def test_the_three_controllers_side_by_side(robot1) -> None:
    sdir, s = robot1
    for task in s["tasks"].values():
        assert task["median_improvement_compensated"] == task["median_improvement"]
        assert all(i["compensated"] is not None for i in task["indices"])
    # The same joints as signature control (the rewrite through the design model loses
    # nothing) and, with the signature run's servo draws, the same readings.
    prog = read_table(stage_path(sdir, "evaluate_program")).to_pylist()
    q = {(r["task"], r["controller"], r["point"]): np.array(r["q_deg"]) for r in prog}
    diffs = [np.abs(q[(t, "compensated", p)] - v).max()
             for (t, c, p), v in q.items() if c == "signature"]  # fmt: skip
    assert len(diffs) == sum(1 for k in q if k[1] == "compensated") > 100
    assert max(diffs) < 1e-9
    np.testing.assert_array_equal(_values(s, "compensated"), _values(s, "signature"))
    report = (sdir / "report" / "evaluation.md").read_text()
    assert "improvement, compensated" in report


def test_the_compensated_targets_go_through_the_design_model(robot1) -> None:
    """Not a copy of signature control: the design controller is given other poses than
    the desired ones (by the design model's error) and solves them back to the same joints."""
    sdir, _ = robot1
    sig = load_signature(sdir / "signature.json")
    design = DesignModel(sig.robot, np.eye(4))
    model = CompensatedModel(design, SignatureModel(sig, 0.0))
    rng = np.random.default_rng(1)
    lim = sig.robot.limits
    q = np.radians(rng.uniform(lim[:, 0] * 0.5, lim[:, 1] * 0.5, (20, 6)))
    T = model.signature.fk(q)
    from pipeline.evaluation.controllers import plan_branches

    branches = plan_branches(sig.robot, np.eye(4), T)
    q_s, T_c, ok = model.compensated_targets(T, branches, q[0])
    moved = np.linalg.norm(T_c[ok, :3, 3] - T[ok, :3, 3], axis=-1)
    assert ok.sum() >= 15 and moved.min() > 0.05  # cm: the design model's error
    q_c, ok_c = model.solve(T, branches, q[0])
    assert np.abs(q_c[ok_c] - q_s[ok_c]).max() < 1e-8


def test_noiseless_compensated_control_is_exact(tmp_path) -> None:
    sdir = tmp_path / "s"
    simulate_session(sdir, SimulationOptions(seed=4, noiseless=True, points=12, repeats=1,
                                             sigmas=ErrorSigmas()))  # fmt: skip
    s = evaluate(sdir, rig=EXACT_RIG, report=False).summary
    assert np.abs(_values(s, "compensated")).max() <= 1e-5
    assert np.abs(_values(s, "design")).max() > 0.05


def test_a_recording_without_the_compensated_run_is_scored_for_the_others(robot1, tmp_path) -> None:
    """A hardware session's evaluation.mcap recorded before the compensated controller
    existed: the design and signature indices as before, the compensated ones null."""
    sdir, s = robot1
    other = tmp_path / "hw"
    shutil.copytree(sdir, other, ignore=shutil.ignore_patterns("stages", "report"))
    (other / "rig-truth.json").unlink()  # a hardware session: evaluation.mcap is its own
    rec = read_evaluation(other / "evaluation.mcap")
    messages = [Message("/eval/description", 1, rec.description)]
    t = 2
    for topic, rows in (("/eval/teach", rec.teach), ("/eval/program", rec.program),
                        ("/eval/measurement", rec.measurements)):  # fmt: skip
        for r in rows:
            if r.get("controller") != "compensated":
                messages.append(Message(topic, t, r))
                t += 1
    write_recording(other / "evaluation.mcap", messages, EVAL_CHANNELS)
    hw = evaluate(other, report=True).summary
    np.testing.assert_array_equal(_values(hw, "signature"), _values(s, "signature"))
    np.testing.assert_array_equal(_values(hw, "design"), _values(s, "design"))
    assert all(i["compensated"] is None for t in hw["tasks"].values() for i in t["indices"])
    assert all("median_improvement_compensated" not in t for t in hw["tasks"].values())
    assert "| —" in (other / "report" / "evaluation.md").read_text()
