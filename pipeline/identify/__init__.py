"""``identify``: recording -> cached stages -> signature.json -> report, under the session lock.

A plain run (no ``force``, ``from_stage``, ``only`` or ``overrides``) that finds the
session folder and the code as its last complete run left them answers from that run's
record (:mod:`pipeline.identify.record`): the runner, the stage modules, numpy and
pyarrow are imported only when there is something to check or to do (issue 18).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from pipeline.errors import os_errors_refused
from pipeline.identify import record
from pipeline.progress import Progress
from pipeline.signature.verdict import SignatureVerdict, verdict_of
from pipeline.stages.base import StageRun, session_folder
from pipeline.stages.lock import session_lock


@dataclass(frozen=True)
class IdentifyResult:
    """``signature`` and ``report`` are None when not written (``warnings`` says why);
    ``verdict``: the verdict line (``NAME: PASS  predicted …``), None without one;
    ``assessment``: that verdict as data (status, reasons with their numbers and
    thresholds) from the signature written, None without one."""

    runs: list[StageRun]
    signature: Path | None
    report: Path | None
    warnings: list[str]
    verdict: str | None = None
    assessment: SignatureVerdict | None = None


def identify(
    session_dir: str | Path,
    *,
    force: bool = False,
    from_stage: str | None = None,
    only: str | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    report: bool = True,
    progress: TextIO | None = None,
) -> IdentifyResult:
    """Bring the session's stages and signature up to date, then write its report
    (``progress``: where the progress line of the stages goes; None: silent)."""
    sdir = session_folder(session_dir)
    plain = not force and from_stage is None and only is None and not overrides
    with session_lock(sdir):  # one lock for stages, signature and report
        done = record.recall(sdir, report) if plain else None
        if done is not None:
            return _replayed(sdir, done, progress)
        result = _run(sdir, force, from_stage, only, overrides, report, progress)
        if plain and result.signature is not None:
            record.remember(
                sdir,
                report,
                [r.name for r in result.runs],
                str(result.signature.relative_to(sdir)),
                None if result.report is None else str(result.report.relative_to(sdir)),
                result.warnings,
                result.verdict,
            )
    return result


def _replayed(sdir: Path, done: dict[str, Any], progress: TextIO | None) -> IdentifyResult:
    """What the runner would return for a session the record says is complete."""
    runs = record.replay(done)
    bar = Progress("identify", len(runs) - 1, progress, unit="stages")  # as the runner's
    for _ in runs[:-1]:
        bar.step()
    report = None if done["report"] is None else sdir / done["report"]
    sig = sdir / done["signature"]  # its bytes are those of the record's run (its digest)
    assessment = verdict_of(json.loads(sig.read_text(encoding="utf-8")))
    return IdentifyResult(runs, sig, report, done["warnings"], done["verdict"], assessment)


def _run(
    sdir: Path,
    force: bool,
    from_stage: str | None,
    only: str | None,
    overrides: Mapping[str, Mapping[str, Any]] | None,
    report: bool,
    progress: TextIO | None,
) -> IdentifyResult:
    """The runner's full check and work (call under the session lock)."""
    from pipeline.signature.file import FILE_NAME, read_signature_document
    from pipeline.stages.catalog import PRODUCT
    from pipeline.stages.runner import run
    from pipeline.stages.verdict import verdict_line

    runs = run(
        sdir,
        force=force,
        from_stage=from_stage,
        only=only,
        overrides=overrides,
        progress=progress,
    )
    product = [r for r in runs if r.name == PRODUCT[0]]
    if not product and any(r.name == "flange_poses" for r in runs):  # no arm (issue 40)
        return _hand_eye(sdir, runs, report)
    if not product:  # a stage list without a product
        names = ", ".join(r.name for r in runs)
        why = (
            f"{FILE_NAME} not written: this session's stages ({names}) end before a "
            "signature (stages/camera_fit.arrow holds the camera's fit, report/report.md "
            "its report)"
        )
        camera = any(r.name == "camera_fit" for r in runs)
        rep = _camera_report(sdir) if camera and report else None
        return IdentifyResult(runs, None, rep, [why, *_camera_warnings(sdir, runs)])
    if product[0].action == "not written":
        why = (
            f"{FILE_NAME} not written: stages after --only {only} are stale; "
            f"`pipeline identify {sdir}` brings them and the signature up to date"
        )
        return IdentifyResult(runs, None, None, [why])
    sig = sdir / FILE_NAME
    doc = read_signature_document(sig)
    rep = _report_if_stale(sdir, doc["provenance"]["stages"]) if report else None
    line = verdict_line(sdir)
    return IdentifyResult(runs, sig, rep, doc["warnings"], line, verdict_of(doc))


def _hand_eye(sdir: Path, runs: list[Any], report: bool) -> IdentifyResult:
    """A camera session of flange poses without joints: the camera's calibration file,
    ``camera_info.yaml``, the report and the verdict line; no signature (no arm)."""
    from pipeline.report.hand_eye import write_hand_eye_products

    out = write_hand_eye_products(sdir, report)
    why = (f"signature.json not written: flange poses without joint readings calibrate the "
           f"camera, not the arm; the camera's calibration is {out.result.name} and "
           f"{out.camera_info.name}")  # fmt: skip
    return IdentifyResult(runs, None, out.report, [why, *_camera_warnings(sdir, runs)],
                          out.verdict)  # fmt: skip


def _camera_warnings(sdir: Path, runs: list[Any]) -> list[str]:
    """The camera fit's warning (parameters it held), when the session has that stage."""
    if not any(r.name == "camera_fit" for r in runs):
        return []
    from pipeline.stages.camera_fit import camera_warning
    from pipeline.stages.runner import stage_path
    from pipeline.stages.tables import read_table

    line = camera_warning(read_table(stage_path(sdir, "camera_fit")))
    return [] if line is None else [line]


def _camera_report(sdir: Path) -> Path:
    from pipeline.report.camera import write_camera_report

    return write_camera_report(sdir)


def _report_if_stale(sdir: Path, hashes: dict[str, str | None]) -> Path:
    """Write the report unless the existing one was made from the same stage outputs; an
    OSError while writing it (no space, a file size limit) in one line."""
    from pipeline.atomic import write_unless_same_inputs
    from pipeline.signature.file import FILE_NAME

    def write() -> Path:
        if "camera_fit" in hashes:  # a camera session's report (issue 39)
            return _camera_report(sdir)
        from pipeline.report.identification import write_report  # matplotlib: when needed

        return write_report(sdir)

    report = sdir / "report"
    fix = (f"the signature is written ({sdir / FILE_NAME}); free space or raise the file "
           f"size limit, then `pipeline identify {sdir}` writes the report")  # fmt: skip
    with os_errors_refused(report, fix, always_path=True):  # a full disk, `ulimit -f` (issue 44)
        return write_unless_same_inputs(
            report / "report.md", report / ".inputs.json", hashes, write
        )
