"""``identify``: recording -> cached stages -> signature.json -> report."""

from __future__ import annotations

import json
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
    from pipeline.atomic import write_text_atomic

    stamp = sdir / "report" / ".inputs.json"
    current = json.dumps(hashes, sort_keys=True)
    report = sdir / "report" / "report.md"
    if report.is_file() and stamp.is_file() and stamp.read_text() == current:
        return report
    from pipeline.report.identification import write_report  # matplotlib: only when needed

    path = write_report(sdir)
    write_text_atomic(stamp, current)
    return path
