"""One row of ``fleet.arrow`` per session, read from the session's own checked files.

Nothing here computes a result anew: every number is read from the session's
signature.json (checked on read: schema, digest, numbers), its ``validation`` stage
(point sessions), its ``verdict`` stage (predicted accuracy, PASS/CHECK/FAIL), or the
summary of the evaluation that the fleet task just ran.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from pipeline.signature.checks import DIGEST_KEY
from pipeline.signature.file import FILE_NAME, read_signature_document
from pipeline.stages.runner import stage_path
from pipeline.stages.session import session_robot_id, session_sensor
from pipeline.stages.tables import read_table

#: The S-Model's parameters per joint (``signature.json`` ``smodel.parameters``).
SMODEL_PARAMETERS = ("beta_deg", "d_bar_cm", "a_bar_cm", "alpha_bar_deg", "gamma_deg", "b_cm")
#: Why a sonic session has no validation numbers (``pipeline fleet validate``).
NO_VALIDATION = (
    "no validation numbers: a sonic session's targets sit on the links, not on the tool, "
    "so it has no `validation` stage; `pipeline fleet evaluate` measures its accuracy"
)


@dataclass(frozen=True)
class Column:
    name: str
    type: pa.DataType
    unit: str
    description: str


def _c(name: str, t: pa.DataType, unit: str, description: str) -> Column:
    return Column(name, t, unit, description)


COLUMNS = (
    _c("session", pa.string(), "", "session folder as given on the command line"),
    _c("command", pa.string(), "", "fleet command that produced the row"),
    _c("robot", pa.string(), "", "robot description name (the model) recorded in the session"),
    _c("robot_id", pa.string(), "",
       "the arm's own id (serial) recorded in the session (simulate or import --robot-id); "
       "null: none recorded"),
    _c("sensor", pa.string(), "", "recorded sensor kind: sonic or points"),
    _c("recording_sha256", pa.string(), "", "SHA-256 of recording.mcap"),
    _c("signature_sha256", pa.string(), "", "self-digest of signature.json"),
    _c("identified_utc", pa.timestamp("s", tz="UTC"), "", "signature.json created (UTC)"),
    _c("points", pa.int64(), "", "measured positions used by the feature fits (all joints)"),
    _c("sigma_normal_max_cm", pa.float64(), "cm", "largest feature normal residual σ"),
    _c("sigma_radial_max_cm", pa.float64(), "cm", "largest circle radial residual σ"),
    _c("design_misfit_rms_cm", pa.float64(), "cm",
       "RMS design-model vs signature position difference after alignment (no ground truth)"),
    _c("check_points", pa.int64(), "", "validation (check) configurations measured"),
    _c("check_rms_cm", pa.float64(), "cm", "signature position error RMS on check points"),
    _c("check_max_cm", pa.float64(), "cm", "signature position error max on check points"),
    _c("check_registered_rms_cm", pa.float64(), "cm", "the same RMS after base registration"),
    _c("check_design_rms_cm", pa.float64(), "cm",
       "the design model's RMS on the check points, its base and tool registered to the fit "
       "points (the uncalibrated arm: the before of the before/after)"),
    _c("fit_rms_cm", pa.float64(), "cm", "signature position error RMS on the fit points"),
    _c("fit_design_rms_cm", pa.float64(), "cm",
       "the registered design model's RMS on the fit points"),
    _c("gain_evaluation", pa.float64(), "",
       "median over tasks of the median |design| / |signature| index of the measured "
       "evaluation (pipeline fleet evaluate only)"),
    _c("predicted_rms_cm", pa.float64(), "cm",
       "predicted RMS tool position error after alignment (stage verdict; null: no refinement)"),
    _c("predicted_p95_cm", pa.float64(), "cm", "95th percentile of that error over the workspace"),
    _c("verdict", pa.string(), "", "PASS, CHECK or FAIL (stage verdict; null: none)"),
    _c("verdict_reasons", pa.list_(pa.string()), "", "the verdict's reasons, one line each"),
    *(
        _c(f"smodel_{p}", pa.list_(pa.float64()), p.rsplit("_", 1)[1], f"S-Model {p} per joint")
        for p in SMODEL_PARAMETERS
    ),
    _c("warnings", pa.list_(pa.string()), "", "warnings of the signature and the fleet task"),
    _c("error", pa.string(), "", "one-line error of a failed session (null: done)"),
    _c("task_s", pa.float64(), "s", "wall time of the session's task on its worker"),
)  # fmt: skip

SCHEMA = pa.schema(
    [
        pa.field(c.name, c.type, metadata={"unit": c.unit, "description": c.description})
        for c in COLUMNS
    ]
)


def empty_row(session: str, command: str) -> dict[str, Any]:
    """A row with only ``session`` and ``command`` set."""
    row: dict[str, Any] = {c.name: None for c in COLUMNS}
    row.update(session=session, command=command, warnings=[])
    return row


def _max(values: list[Any]) -> float | None:
    finite = [float(v) for v in values if v is not None and np.isfinite(v)]
    return max(finite) if finite else None


def session_row(
    sdir: Path, command: str, evaluation: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The row of an identified session (``evaluation``: its evaluation summary, if run)."""
    import datetime as dt

    from pipeline.report.validation import role_errors, validation_table

    doc = read_signature_document(sdir / FILE_NAME)
    session = read_table(stage_path(sdir, "session"))
    acc = doc["feature_accuracy"]
    row = empty_row(str(sdir), command)
    row.update(
        robot=doc["robot"],
        robot_id=session_robot_id(session),
        sensor=session_sensor(session),
        recording_sha256=doc["provenance"]["recording_sha256"],
        signature_sha256=doc[DIGEST_KEY],
        identified_utc=dt.datetime.fromisoformat(doc["provenance"]["created"]),
        points=int(sum(f["n_points"] for f in acc)),
        sigma_normal_max_cm=_max([f["sigma_normal_cm"] for f in acc]),
        sigma_radial_max_cm=_max([f["sigma_radial_cm"] for f in acc]),
        design_misfit_rms_cm=float(doc["design_alignment"]["rms_misfit_cm"]),
        warnings=list(doc["warnings"]),
    )
    params = doc["smodel"]["parameters"]
    for p in SMODEL_PARAMETERS:
        row[f"smodel_{p}"] = [float(j[p]) for j in params]
    verdict = stage_path(sdir, "verdict")
    if verdict.is_file():
        v = read_table(verdict).to_pylist()[0]
        row.update(
            predicted_rms_cm=v["predicted_rms_cm"],
            predicted_p95_cm=v["predicted_p95_cm"],
            verdict=v["verdict"],
            verdict_reasons=list(v["reasons"]),
        )
    table = validation_table(stage_path(sdir, "validation"))
    roles = role_errors(table)
    if "fit" in roles:
        row.update(fit_rms_cm=roles["fit"]["rms_cm"],
                   fit_design_rms_cm=roles["fit"]["design_registered_rms_cm"])  # fmt: skip
    if "check" in roles:
        e = roles["check"]
        row.update(
            check_points=e["n"],
            check_rms_cm=e["rms_cm"],
            check_max_cm=e["max_cm"],
            check_registered_rms_cm=e["registered_rms_cm"],
            check_design_rms_cm=e["design_registered_rms_cm"],
        )
    elif command == "validate":
        row["warnings"].append(
            NO_VALIDATION if table is None else "no validation (check) configurations recorded"
        )
    if evaluation is not None:
        found = [
            t["median_improvement"]
            for t in evaluation["tasks"].values()
            if t["median_improvement"] is not None
        ]
        row["gain_evaluation"] = float(np.median(found)) if found else None
        row["warnings"] += [f"{k} skipped: {v}" for k, v in evaluation["skipped"].items()]
    return row


def fleet_table(rows: list[dict[str, Any]]) -> pa.Table:
    """The rows as a table of :data:`SCHEMA`, sorted by session."""
    return pa.Table.from_pylist(sorted(rows, key=lambda r: r["session"]), schema=SCHEMA)
