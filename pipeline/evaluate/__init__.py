"""``evaluate``: identification (cached) -> teach -> programs -> run -> indices -> report.

For a simulated session (``rig-truth.json`` beside the recording) the
evaluation rig (:mod:`pipeline.rig.evaluation`) records ``evaluation.mcap``:
the teaching first, and the programs and instrument readings whenever the
programs differ from those recorded (a new signature). A hardware session
brings its own ``evaluation.mcap``. Scoring reads only the recording.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from pipeline.contract.evaluation import read_evaluation
from pipeline.progress import Progress
from pipeline.report.evaluation_summary import summarize
from pipeline.stages.catalog import EVALUATE_STAGE_MODULES
from pipeline.stages.lock import session_lock
from pipeline.stages.runner import StageRun, run, session_folder, stage_path
from pipeline.stages.tables import read_provenance, read_table


@dataclass(frozen=True)
class EvaluateResult:
    """What ``evaluate`` did and found."""

    identify_runs: list[StageRun]
    runs: list[StageRun]
    recorded: list[str]  # "teach" and/or "program" when the rig (re)recorded them
    report: Path | None
    summary: dict[str, Any]


def _program_payloads(program: Any, units: list[str]) -> list[dict[str, Any]]:
    from pipeline.stages.evaluate_measurements import recorded_program_rows

    return [
        {"task": t, "controller": c, "point": p, "q_commanded": list(q), "units": units}
        for t, c, p, q in recorded_program_rows(program)
    ]


def evaluate(
    session_dir: str | Path,
    *,
    rig: Any | None = None,
    report: bool = True,
    progress: TextIO | None = None,
) -> EvaluateResult:
    """Evaluate a session's signature against its design model on the grid-touching tasks.

    Parameters
    ----------
    session_dir : the session folder.
    rig : :class:`pipeline.rig.evaluation.EvaluationRigOptions` or None
        Simulated sessions only: the rig's switches. A recording made with
        other switches is redone; None keeps whatever was recorded (defaults
        for a first recording).
    report : write ``report/evaluation.md`` (when its inputs changed).
    progress : where the progress lines of the identification and evaluation stages go
        (None: silent).
    """
    sdir = session_folder(session_dir)
    with session_lock(sdir):  # one lock for the identification, the rig and the stages
        return _evaluate(sdir, rig, report, progress)


def _evaluate(sdir: Path, rig: Any | None, report: bool, progress: TextIO | None) -> EvaluateResult:
    from pipeline.identify import identify

    ident = identify(sdir, report=report, progress=progress)
    path = sdir / "evaluation.mcap"
    simulated = (sdir / "rig-truth.json").is_file()
    # One bar over the evaluation's work (the identification drew its own): the rig's two
    # recordings (a simulated session), the first two stages, the four stages again (the
    # rig may have re-recorded their input), the report. Cold, the recordings and the
    # first stages are nearly all of it (the solver's kernels compile).
    steps = (2 if simulated else 0) + 2 + len(EVALUATE_STAGE_MODULES) + (1 if report else 0)
    bar = Progress("evaluate", steps, progress, unit="steps")
    try:
        recorded, runs = _record_and_run(sdir, rig, simulated, path, bar)
        summary = summarize(sdir)
        rep = _report_if_stale(sdir) if report else None
        if report:
            bar.step()
    finally:
        bar.close()
    return EvaluateResult(ident.runs, runs, recorded, rep, summary)


def _record_and_run(
    sdir: Path, rig: Any | None, simulated: bool, path: Path, bar: Progress
) -> tuple[list[str], list[StageRun]]:
    """Record the teaching and the programs on the simulated rig when needed, and run
    the evaluation stages; what was recorded and the stages' runs (``bar`` stepped)."""
    recorded: list[str] = []
    if simulated:
        from pipeline.rig.evaluation import EvaluationRigOptions, record_evaluation

        opts = rig or EvaluationRigOptions()
        if not path.is_file() or (
            rig is not None and _recorded_options(read_evaluation(path).description) != rig
        ):
            record_evaluation(sdir, None, opts)
            recorded.append("teach")
        else:
            opts = _recorded_options(read_evaluation(path).description)
        bar.step()
    first_runs = run(sdir, modules=EVALUATE_STAGE_MODULES[:2], progress=bar)
    first = {r.name: r for r in first_runs if r.action == "ran"}
    if simulated:
        from pipeline.stages.evaluate_measurements import COMMAND_TOL, program_matches

        program = read_table(stage_path(sdir, "evaluate_program"))
        rec = read_evaluation(path)
        # The rig re-records a program the measurement stage would refuse, not one within its
        # COMMAND_TOL (1e-6 deg / cm): another CPU's BLAS kernels move the solved joints by
        # ~1e-13 deg (AMD EPYC against the machine that recorded robot1-7), and the exact
        # test rewrote the committed evaluation.mcap of every session on such a machine.
        if not program_matches(rec.program, program, COMMAND_TOL):
            units = rec.teach[0]["units"]
            record_evaluation(sdir, _program_payloads(program, units), opts)
            recorded.append("program")
        bar.step()
    runs = [first.get(r.name, r) for r in run(sdir, modules=EVALUATE_STAGE_MODULES, progress=bar)]
    return recorded, runs


def _recorded_options(description: dict[str, Any]) -> Any:
    from pipeline.rig.evaluation import EvaluationRigOptions

    return EvaluationRigOptions(
        perfect_servo=description.get("servo") == "perfect",
        exact_instruments=description.get("instruments") == "exact",
    )


def _report_if_stale(sdir: Path) -> Path:
    """Write ``report/evaluation.md`` unless it was made from the same stage outputs."""
    from pipeline.atomic import write_unless_same_inputs

    hashes = {
        m: read_provenance(stage_path(sdir, m)).get("content_hash") for m in EVALUATE_STAGE_MODULES
    }

    def write() -> Path:
        from pipeline.report.evaluation import write_evaluation_report  # matplotlib: when needed

        return write_evaluation_report(sdir)

    report = sdir / "report"
    return write_unless_same_inputs(
        report / "evaluation.md", report / ".evaluation-inputs.json", hashes, write
    )
