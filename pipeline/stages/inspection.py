"""A session's stages looked at, never run: their status (``pipeline status``) and one
stage table with its provenance (``pipeline show``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa

from pipeline.errors import ArmsigError
from pipeline.stages.base import session_folder
from pipeline.stages.catalog import EVALUATE_STAGE_MODULES
from pipeline.stages.runner import StageStatus, identification_modules, stage_path, status
from pipeline.stages.tables import check_table, read_provenance, read_table


def session_status(session_dir: str | Path) -> list[StageStatus]:
    """Every stage of a session as fresh, stale or missing, and why: the identification
    stages, ``signature.json``, then, once the session has an ``evaluation.mcap``, the
    ``pipeline evaluate`` stages."""
    evaluated = (session_folder(session_dir) / "evaluation.mcap").is_file()
    modules = identification_modules(session_dir) + (EVALUATE_STAGE_MODULES if evaluated else ())
    return status(session_dir, modules=modules)


@dataclass(frozen=True)
class StageTable:
    """A stage's output file, its provenance and its table; ``problem``: why the file is
    not the one armsig wrote (e.g. edited since: its content hash differs), else empty."""

    path: Path
    provenance: dict[str, Any]
    table: pa.Table
    problem: str = ""


def stage_table(
    session_dir: str | Path, stage: str, columns: Sequence[str] | None = None
) -> StageTable:
    """The output of ``stage`` (e.g. ``features``), with just ``columns`` when given."""
    path = stage_path(Path(session_dir), stage)
    if not path.is_file():
        raise ArmsigError(f"{path}: no such stage output", fix=f"`pipeline status {session_dir}`")
    provenance = read_provenance(path)
    table = read_table(path)  # a damaged file: one line, not a polars panic
    problem = check_table(path, stage).problem  # the check every consumer of a stage makes
    if columns:
        unknown = [c for c in columns if c not in table.column_names]
        if unknown:
            raise ArmsigError(
                f"{path}: no column {unknown[0]!r}", expected=", ".join(table.column_names)
            )
        table = table.select(list(columns))
    return StageTable(path, provenance, table, problem)
