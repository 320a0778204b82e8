"""``identify``: recording -> cached stages -> signature.json -> report."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pipeline.signature_file import write_signature
from pipeline.stages.runner import StageRun, run


@dataclass(frozen=True)
class IdentifyResult:
    runs: list[StageRun]
    signature: Path
    report: Path | None
    warnings: list[str]


def identify(
    session_dir: str | Path,
    *,
    force: bool = False,
    from_stage: str | None = None,
    only: str | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    report: bool = True,
) -> IdentifyResult:
    """Bring the session's stages up to date, then write its signature and report."""
    sdir = Path(session_dir)
    runs = run(sdir, force=force, from_stage=from_stage, only=only, overrides=overrides)
    sig, doc = write_signature(sdir)
    rep = _report_if_stale(sdir, doc["provenance"]["stages"]) if report else None
    return IdentifyResult(runs, sig, rep, doc["warnings"])


def _report_if_stale(sdir: Path, hashes: dict[str, str | None]) -> Path:
    """Write the report unless the existing one was made from the same stage outputs."""
    from pipeline.atomic import write_unless_same_inputs

    def write() -> Path:
        from pipeline.report.identification import write_report  # matplotlib: when needed

        return write_report(sdir)

    report = sdir / "report"
    return write_unless_same_inputs(report / "report.md", report / ".inputs.json", hashes, write)
