"""Session commands: identify a recorded session and look at it (identify, status, show,
audit, validate)."""

from __future__ import annotations

import sys
from typing import Annotated, Any

import typer

from pipeline.cli.options import (
    ImportFormat,
    JsonOption,
    SessionArg,
    StrictOption,
    choice,
    comma_list,
    stage_params,
)
from pipeline.cli.output import print_json, warn
from pipeline.errors import ArmsigError
from pipeline.signature.verdict import verdict_failed

commands = typer.Typer()


@commands.command()
def identify(
    session: SessionArg,
    force: Annotated[bool, typer.Option(help="Rerun every stage.")] = False,
    from_: Annotated[
        str | None, typer.Option("--from", help="Rerun this stage and every later one.")
    ] = None,
    only: Annotated[str | None, typer.Option(help="Rerun just this stage.")] = None,
    param: Annotated[
        list[str] | None, typer.Option(help="Stage parameter, STAGE.NAME=VALUE (repeatable).")
    ] = None,
    report: Annotated[bool, typer.Option(help="Write report/report.md.")] = True,
    as_json: JsonOption = False,
) -> None:
    """Identify the arm signature of a recorded session (stages, signature.json, report)."""
    from pipeline.identify import identify as run_identify

    result = run_identify(
        session,
        force=force,
        from_stage=from_,
        only=only,
        overrides=stage_params(param),
        report=report,
        progress=sys.stderr,
    )
    v = result.assessment
    if as_json:
        print_json(
            {
                "session": session,
                "stages": [_run_dict(r) for r in result.runs],
                "signature": None if result.signature is None else str(result.signature),
                "report": None if result.report is None else str(result.report),
                "warnings": result.warnings,
                "verdict": result.verdict,
                "verdict_detail": None if v is None else v.to_dict(),
                "validation": _validation(session),
            }
        )
    else:
        for r in result.runs:
            if r.action == "ran":
                typer.echo(f"  {r.name:12s} ran     {r.seconds * 1e3:7.1f} ms  {r.rows} rows")
            else:
                typer.echo(f"  {r.name:12s} {r.action}")
    for w in result.warnings:
        warn(w)
    if not as_json:
        typer.echo(f"signature: {result.signature or 'not written'}")
        if result.report:
            typer.echo(f"report:    {result.report}")
        if result.verdict:
            typer.echo(result.verdict)  # the last line (issue 15)
    if v is not None and v.failed:  # the output is complete: exit 4 (issue 30)
        raise verdict_failed(v, session, "see the reasons above and docs/verdict.md")


def _run_dict(r: Any) -> dict[str, Any]:
    """A :class:`~pipeline.stages.base.StageRun` for ``--json`` (wall and CPU seconds and
    rows of a stage that ran, else null)."""
    ran = r.action == "ran"
    return {
        "name": r.name,
        "action": r.action,
        "seconds": round(r.seconds, 4) if ran else None,
        "cpu_seconds": round(r.cpu_seconds, 4) if ran else None,
        "rows": r.rows if ran else None,
    }


@commands.command()
def status(session: SessionArg, as_json: JsonOption = False) -> None:
    """Show every stage of a session as fresh, stale or missing, and why.

    The identification stages, signature.json, then, once the session has an
    evaluation.mcap, the `pipeline evaluate` stages.
    """
    from pipeline.stages.inspection import session_status

    states = session_status(session)
    if as_json:
        print_json([{"name": s.name, "state": s.state, "reason": s.reason} for s in states])
        return
    for st in states:
        typer.echo(f"  {st.name:21s} {st.state:8s} {st.reason}")


@commands.command()
def show(
    session: SessionArg,
    stage: Annotated[str, typer.Argument(help="Stage name, e.g. features.")],
    rows: Annotated[
        int | None, typer.Option(min=0, help="Rows to print (default: 20; with --json, all).")
    ] = None,
    columns: Annotated[
        str | None, typer.Option(help="Comma-separated columns to print (default: all).")
    ] = None,
    as_json: JsonOption = False,
) -> None:
    """Print a stage table (polars) with its provenance."""
    import json

    import polars as pl

    from pipeline.stages.inspection import stage_table

    st = stage_table(session, stage, None if columns is None else comma_list(columns))
    if st.problem:  # shown as it is, but not as armsig's (issue 32); stderr in both modes
        warn(f"{st.path}: {st.problem}; try: `pipeline identify {session} --force` rewrites it")
    if as_json:
        shown = st.table if rows is None else st.table.slice(0, rows)
        print_json(
            {
                "path": str(st.path),
                "provenance": st.provenance,
                "n_rows": st.table.num_rows,
                "columns": [_column_dict(f) for f in st.table.schema],
                "rows": shown.to_pylist(),
            }
        )
        return
    n = 20 if rows is None else rows
    typer.echo(json.dumps(st.provenance, indent=1, sort_keys=True))
    with pl.Config(tbl_rows=n, tbl_cols=-1, tbl_width_chars=4000, fmt_str_lengths=60):
        typer.echo(pl.DataFrame(st.table).head(n))


def _column_dict(field: Any) -> dict[str, Any]:
    """A stage table's column for ``show --json``: name, Arrow type, unit and description
    (the field's metadata; null when empty)."""
    meta = {k.decode(): v.decode() for k, v in (field.metadata or {}).items()}
    return {
        "name": field.name,
        "type": str(field.type),
        "unit": meta.get("unit") or None,
        "description": meta.get("description") or None,
    }


@commands.command()
def audit(
    session: SessionArg,
    as_json: JsonOption = False,
    configurations: Annotated[int, typer.Option(help="Random configurations.")] = 1000,
) -> None:
    """Compare the signature and the design model with a simulated session's truth (a
    camera session: its fit's tool pose, hand-eye transforms and lens)."""
    from pipeline.rig.audit import audit as run_audit

    if _is_camera(session):
        _camera_audit(session, as_json)
        return
    r = run_audit(session, configurations=configurations)
    if as_json:
        print_json(r.to_dict())
        return
    typer.echo(f"{r.session}: {r.configurations} random configurations, best-fit base and tool")
    for name, e in (("signature", r.signature), ("design", r.design)):
        typer.echo(
            f"  {name:9s} position max {e.max_position_cm:.3e} cm  rms {e.rms_position_cm:.3e} cm"
            f"   orientation max {e.max_orientation_deg:.3e} deg"
            f"  rms {e.rms_orientation_deg:.3e} deg"
        )
    typer.echo(f"  design / signature RMS position error: {r.improvement:.1f}x")


def _is_camera(session: str) -> bool:
    from pathlib import Path

    from pipeline.stages.runner import stage_path

    return stage_path(Path(session), "camera_fit").is_file()


def _camera_audit(session: str, as_json: bool) -> None:
    from pipeline.rig.camera_audit import CONFIGURATIONS, audit_camera_session

    r = audit_camera_session(session)
    if as_json:
        print_json({"session": session, **r.to_dict()})
        return
    typer.echo(f"{session}: camera fit against the truth, {CONFIGURATIONS} random configurations")
    typer.echo(f"  tool pose     max {r.tool_position_cm:.3e} cm  {r.tool_orientation_deg:.3e} deg")
    typer.echo(f"  fixed body    {r.fixed_position_cm:.3e} cm  {r.fixed_orientation_deg:.3e} deg"
               " (in the true base)")  # fmt: skip
    typer.echo(f"  flange body   {r.flange_position_cm:.3e} cm  {r.flange_orientation_deg:.3e} deg"
               " (on the true flange)")  # fmt: skip
    typer.echo(f"  intrinsics    max relative error {r.intrinsics_relative:.3e}")


@commands.command()
def validate(
    session: SessionArg,
    against: Annotated[
        list[str],
        typer.Option(
            help="A second file of measured points; repeat it (or give a quoted "
            "glob) for several files of one validation set, in order."
        ),
    ],
    format: Annotated[
        ImportFormat, choice("sscanss2, table, rct, mat or rosbag2 (docs/import.md).")
    ],
    map: Annotated[str | None, typer.Option(help="Map file (TOML) of the second file.")] = None,
    strict: StrictOption = False,
    tool_point: Annotated[
        str | None,
        typer.Option(
            "--tool-point",
            help="'registered': the file measured another point on the tool; locate it (and "
            "the base) by the fit of the file's own points, and say so. A target ID: locate "
            "it from its rows at the map's tool_point_q (readings), judge the other rows.",
        ),
    ] = None,
    as_json: JsonOption = False,
) -> None:
    """The signature's position error on a second file (read in memory, nothing written).

    Every row is a pose to check (no sweeps needed); its target must be the session's tool
    point (matched by id). The design model with its base and tool registered to the same
    points is shown beside the signature (the error without the calibration).
    """
    from pipeline.evaluate.validate import validate_against

    r = validate_against(session, list(against), format.value, map, strict, tool_point)
    if as_json:
        print_json(r)
        return
    typer.echo(
        f"{r['file']}: {r['n']} points of target {r['target']} vs the signature of {session}"
    )
    for note in r["notes"]:  # rows dropped for a missing value (issue 42), σ floored
        warn(note)
    if r["rows_skipped"] and not r["notes"]:  # said, not skipped silently (issue 32)
        warn(f"{r['rows_skipped']} row(s) of {r['file']} skipped: a reading or coordinate "
             "is not a finite number (NaN or inf)")  # fmt: skip
    if r["tool_point"] == "registered":  # issue 42: a point the session never measured
        x, y, z = r["tool_point_local_cm"]
        typer.echo(
            f"  tool point registered: located by the fit of this file at ({x:.4g}, {y:.4g}, "
            f"{z:.4g}) cm in the last link's frame, {r['tool_point_offset_cm']:.4g} cm from "
            "the session's tool point, with the base (9 parameters fitted to the points "
            "judged, as the design model below)"
        )
        typer.echo(
            f"  base and tool point registered:  mean {r['mean_cm']:.4g}  RMS {r['rms_cm']:.4g}"
            f"  max {r['max_cm']:.4g} cm"
        )
    else:
        if r["tool_point"] != "session":  # located at the map's tool_point_q (issue 42)
            x, y, z = r["tool_point_local_cm"]
            typer.echo(
                f"  tool point {r['tool_point']}: located from its {r['tool_point_rows']} "
                f"row(s) at the map's tool_point_q, at ({x:.4g}, {y:.4g}, {z:.4g}) cm in the last "
                f"link's frame, {r['tool_point_offset_cm']:.4g} cm from the session's tool "
                "point; the other rows judged"
            )
        typer.echo(
            f"  as measured:      mean {r['mean_cm']:.4g}  RMS {r['rms_cm']:.4g}  "
            f"max {r['max_cm']:.4g} cm"
        )
    if r["tool_point"] == "registered":
        pass  # the signature's registered line above
    elif r["registered_rms_cm"] is None:
        typer.echo("  base registered:  not possible (fewer than 3 points, or collinear)")
    else:
        typer.echo(
            f"  base registered:  mean {r['registered_mean_cm']:.4g}  "
            f"RMS {r['registered_rms_cm']:.4g}  max {r['registered_max_cm']:.4g} cm"
        )
    typer.echo(
        f"  design model, base and tool registered:  mean {r['design_registered_mean_cm']:.4g}  "
        f"RMS {r['design_registered_rms_cm']:.4g}  max {r['design_registered_max_cm']:.4g} cm"
    )
    if r["predicted_rms_cm"] is not None:  # issue 41: the prediction at these very poses
        gain = "" if r["gain_registered"] is None else (
            f"; measured gain {r['gain_registered']:.2f}× the registered design")  # fmt: skip
        typer.echo(
            f"  predicted at these poses: RMS {r['predicted_rms_cm']:.4g} cm (the parameters' "
            f"part and the unmodelled error){gain}"
        )


def _validation(session: str) -> dict[str, Any] | None:
    """The session's ``validation`` numbers per role (signature, and the registered design
    model beside it: issue 29), None without the stage (a sonic session) or a session folder."""
    from pipeline.report.validation import role_errors, validation_table
    from pipeline.stages.runner import session_folder, stage_path

    try:
        table = validation_table(stage_path(session_folder(session), "validation"))
    except ArmsigError:
        return None
    return None if table is None else role_errors(table)
