"""``pipeline evaluate``: recorded, cached, scored from measurements only (issue 6)."""

import json
import shutil
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from committed import committed_sessions

from pipeline.contract.evaluation import read_evaluation
from pipeline.errors import ArmsigError, StageError
from pipeline.evaluate import evaluate
from pipeline.rig.evaluation import EvaluationRigOptions
from pipeline.rig.recorder import EVAL_CHANNELS
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.rig.true_robot import ErrorSigmas
from pipeline.schemas import mcap_json_schema

ROBOT1 = Path(__file__).resolve().parent.parent / "sessions" / "robot1"
EXACT_RIG = EvaluationRigOptions(perfect_servo=True, exact_instruments=True)
# Issue 6 acceptance: scoring adds no error beyond 1e-5 (cm or deg); the solvers stop
# at 1e-7 cm / 1e-10 rad, the measured worst case is ~1e-7.
EXACT_TOL = 1e-5


def _copy_session(dst: Path, src: Path = ROBOT1) -> Path:
    """A copy of a session (default robot1) with whatever identification it has, but
    without any evaluation: no recording, no ``evaluate_*`` stages."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("evaluat*", ".evaluation*"))
    return dst


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> tuple[Path, object]:
    sdir = _copy_session(tmp_path_factory.mktemp("eval") / "robot1")
    return sdir, evaluate(sdir, report=False)


def _all(summary: dict, who: str) -> np.ndarray:
    return np.array([abs(i[who]) for t in summary["tasks"].values() for i in t["indices"]])


def test_every_task_scored_with_acceptance(session) -> None:
    _, r = session
    s = r.summary
    assert set(s["tasks"]) == {"lines1d", "grid2d", "grid3d", "grid12"} and not s["skipped"]
    sizes = {t: len(v["indices"]) for t, v in s["tasks"].items()}
    assert sizes == {"lines1d": 6, "grid2d": 5, "grid3d": 12, "grid12": 34}
    assert s["tasks"]["grid12"]["median_improvement"] >= 3.0
    assert max(s["grid12_signature_radial_cm"].values()) < 0.05
    assert r.recorded == ["teach", "program"]


def test_recording_follows_its_schemas(session) -> None:
    from mcap.reader import make_reader

    sdir, _ = session
    topics = set()
    with (sdir / "evaluation.mcap").open("rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages():
            topics.add(channel.topic)
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
    assert topics == set(EVAL_CHANNELS)
    assert mcap_json_schema("eval_measurement")["title"] == "armsig.EvalMeasurement"


def test_teach_readings_are_encoder_counts(session) -> None:
    sdir, _ = session
    q = np.array([m["q_encoder"] for m in read_evaluation(sdir / "evaluation.mcap").teach])
    counts = q / 0.005
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)


def test_second_run_does_no_work(session) -> None:
    sdir, _ = session
    mtime = (sdir / "evaluation.mcap").stat().st_mtime_ns
    r = evaluate(sdir, report=False)
    assert {x.action for x in r.runs} == {"cached"}
    assert {x.action for x in r.identify_runs} == {"cached"}
    assert r.recorded == [] and (sdir / "evaluation.mcap").stat().st_mtime_ns == mtime


def test_new_signature_reruns_the_program(tmp_path) -> None:
    sdir = _copy_session(tmp_path / "robot1")
    first = evaluate(sdir, report=False)
    doc = json.loads((sdir / "signature.json").read_text())
    doc["smodel"]["links"][1][0][3] += 0.05  # a different signature, same stage provenance
    (sdir / "signature.json").write_text(_resealed(doc))  # an edit with a valid digest
    r = evaluate(sdir, report=False)
    actions = {x.name: x.action for x in r.runs}
    assert actions["evaluate_program"] == "ran" and actions["evaluate_indices"] == "ran"
    assert r.recorded == ["program"]
    design = [i["design"] for i in r.summary["tasks"]["grid12"]["indices"]]
    assert design == [i["design"] for i in first.summary["tasks"]["grid12"]["indices"]]
    # A hardware session cannot re-run the robot: the stale recording is refused.
    (sdir / "rig-truth.json").unlink()
    doc["smodel"]["links"][1][0][3] += 0.05
    (sdir / "signature.json").write_text(_resealed(doc))
    with pytest.raises(StageError, match="another joint program"):
        evaluate(sdir, report=False)


def _resealed(doc: dict) -> str:
    """A deliberately edited signature with its self-digest recomputed (a hand edit
    without it is corrupt, and ``identify`` rewrites it)."""
    from pipeline.signature.file import signature_text

    return signature_text({k: v for k, v in doc.items() if k != "sha256"})


def test_hardware_session_needs_its_recording(tmp_path) -> None:
    sdir = _copy_session(tmp_path / "robot1")
    (sdir / "rig-truth.json").unlink()
    with pytest.raises(ArmsigError, match="evaluation.mcap"):
        evaluate(sdir, report=False)


def _simulated(tmp_path: Path, sigmas: ErrorSigmas) -> dict:
    sdir = tmp_path / "s"
    # Noiseless: exact ranges and servo, no fixture error; 12 points per sweep suffice.
    simulate_session(sdir, SimulationOptions(seed=4, noiseless=True, points=12, repeats=1,
                                             sigmas=sigmas))  # fmt: skip
    return evaluate(sdir, rig=EXACT_RIG, report=False).summary


def test_noiseless_signature_is_exact(tmp_path) -> None:
    s = _simulated(tmp_path, ErrorSigmas())
    assert len(s["tasks"]) == 4
    assert _all(s, "signature").max() <= EXACT_TOL
    assert _all(s, "design").max() > 0.05  # the design model does err on this robot


def test_design_is_exact_on_a_perfect_robot(tmp_path) -> None:
    s = _simulated(tmp_path, ErrorSigmas(0.0, 0.0, 0.0))
    assert len(s["tasks"]) == 4
    assert _all(s, "design").max() <= EXACT_TOL


def test_cli_json(session) -> None:
    from typer.testing import CliRunner

    from pipeline.cli import app

    sdir, _ = session
    res = CliRunner().invoke(app, ["evaluate", str(sdir), "--json", "--no-report"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)  # stderr: the progress lines
    assert out["tasks"]["grid12"]["median_improvement"] >= 3.0


def test_status_lists_the_evaluate_stages(session, tmp_path) -> None:
    from pipeline.stages.catalog import EVALUATE_STAGE_MODULES, STAGE_MODULES
    from pipeline.stages.runner import status as stage_status

    sdir, _ = session
    both = STAGE_MODULES + EVALUATE_STAGE_MODULES
    assert {s.state for s in stage_status(sdir, modules=both)} == {"fresh"}
    other = _copy_session(tmp_path / "robot1", src=sdir)  # identified, never evaluated
    states = {s.name: s.state for s in stage_status(other, modules=both)}
    assert all(states[m] == "missing" for m in EVALUATE_STAGE_MODULES)
    assert all(states[m] == "fresh" for m in STAGE_MODULES)
    from typer.testing import CliRunner

    from pipeline.cli import app

    res = CliRunner().invoke(app, ["status", str(sdir)])
    assert res.exit_code == 0 and "evaluate_indices" in res.output


def test_fresh_process_with_cached_stages(session, tmp_path) -> None:
    """A new signature evaluated in a new interpreter, every other stage cached: the
    program stage must not rely on a module (pyarrow.compute) that only an earlier
    stage of the same process imported."""
    import subprocess
    import sys

    sdir, _ = session
    other = tmp_path / "robot1"
    shutil.copytree(sdir, other)
    doc = json.loads((other / "signature.json").read_text())
    doc["smodel"]["links"][1][0][3] += 0.05  # a different signature, same stage provenance
    (other / "signature.json").write_text(_resealed(doc))
    res = subprocess.run(
        [sys.executable, "-m", "pipeline.cli", "evaluate", str(other), "--json", "--no-report"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert set(json.loads(res.stdout)["tasks"]) == {"lines1d", "grid2d", "grid3d", "grid12"}


COMMITTED = committed_sessions("evaluation.mcap")


@pytest.mark.parametrize("committed", COMMITTED, ids=lambda p: p.name)
def test_evaluate_keeps_a_committed_evaluation_recording(committed: Path, tmp_path: Path) -> None:
    """`pipeline evaluate sessions/robot5` (a README command) rewrote the committed
    evaluation.mcap of every session: the program recorded in it was not the one the code
    computes now, so the rig recorded it again (issue 30). A change of the evaluation
    program must come with refreshed recordings (run `pipeline evaluate` on each and
    commit them)."""
    d = tmp_path / committed.name
    d.mkdir()
    for name in ("recording.mcap", "evaluation.mcap", "rig-truth.json"):  # what git holds
        shutil.copy(committed / name, d)
    before = (d / "evaluation.mcap").read_bytes()
    result = evaluate(d, report=False)
    assert result.recorded == []
    assert (d / "evaluation.mcap").read_bytes() == before
