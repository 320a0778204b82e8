"""The ``fleet`` group: many sessions at once on Dask (identify, evaluate, validate,
report). The work is in :mod:`pipeline.fleet`."""

from __future__ import annotations

import sys
from typing import Annotated, Any

import typer

from pipeline.cli.options import JsonOption
from pipeline.cli.output import print_json, warn
from pipeline.errors import ArmsigError

commands = typer.Typer(
    help="Many sessions at once on Dask: one task per session, one fleet.arrow for all.",
    no_args_is_help=True,
)

FleetDirs = Annotated[
    list[str], typer.Argument(help="Session folders, or folders to search for sessions.")
]
SchedulerOption = Annotated[
    str | None,
    typer.Option(
        help="Dask scheduler tcp://HOST:PORT (else $DASK_SCHEDULER_ADDRESS, else a local "
        "cluster for this command; `local` forces it)."
    ),
]
FleetWorkers = Annotated[
    int | None,
    typer.Option(min=1, max=256, help="Workers of the local cluster (default: the cores)."),
]
FleetOut = Annotated[
    str | None, typer.Option(help="Folder of fleet.arrow (default: the first DIR).")
]


def _fleet(
    command: str,
    dirs: list[str],
    scheduler: str | None,
    workers: int | None,
    out: str | None,
    as_json: bool,
) -> None:
    """Run ``command`` over the sessions; print one line per session (``as_json``: the
    rows of fleet.arrow as one JSON document), and, after every other one is done and
    fleet.arrow is written, refuse (exit 1) when any session failed, else exit 4 when any
    session's verdict is FAIL (as ``identify`` does)."""
    from pipeline.errors import VerdictFailError
    from pipeline.fleet.run import fleet

    r = fleet(command, dirs, scheduler, workers, out, progress=sys.stderr)
    if as_json:  # the warnings are in the rows, and on stderr as without --json
        print_json({"table": str(r.table), "wall_s": r.wall_s, "failed": len(r.failed),
                    "verdict_fail": len(r.verdict_failed), "sessions": r.rows})  # fmt: skip
        for row in r.rows:
            for w in row["warnings"]:
                warn(f"{row['session']}: {w}")
    else:
        _print_rows(r)
    fails = [row["session"] for row in r.verdict_failed]
    also = f"; {len(fails)} more identified with verdict FAIL" if fails else ""
    if r.failed:
        raise ArmsigError(
            f"{len(r.failed)} of {len(r.rows)} sessions failed (the others are done){also}",
            fix=f"see the error column of {r.table}; a rerun redoes only what is stale",
        )
    if fails:
        raise VerdictFailError(
            f"{len(fails)} of {len(r.rows)} sessions have the verdict FAIL: "
            + ", ".join(fails[:3])
            + (f" and {len(fails) - 3} more" if len(fails) > 3 else ""),
            fix="see their reasons (`pipeline identify SESSION`, docs/verdict.md)",
        )


def _print_rows(r: Any) -> None:
    """One line per session of a :class:`~pipeline.fleet.run.FleetResult`, its warnings
    on stderr, then the count and the table."""
    for row in r.rows:
        if row["error"] is not None:
            typer.echo(f"  FAILED {row['session']}: {row['error']}")
            continue
        extra = (
            f"  check RMS {row['check_rms_cm']:.4g} cm" if row["check_rms_cm"] is not None
            else ""
        ) + (
            f"  gain {row['gain_evaluation']:.3g}" if row["gain_evaluation"] is not None else ""
        )  # fmt: skip
        done = row["verdict"] or "ok"  # PASS / CHECK / FAIL, "ok" without a verdict stage
        typer.echo(f"  {done:6s} {row['session']}: {row['signature_sha256'][:12]}{extra}")
        for w in row["warnings"]:
            warn(f"{row['session']}: {w}")
    typer.echo(f"{len(r.rows)} sessions in {r.wall_s:.1f} s; wrote {r.table}")


@commands.command("identify")
def fleet_identify(
    dirs: FleetDirs,
    scheduler: SchedulerOption = None,
    workers: FleetWorkers = None,
    out: FleetOut = None,
    as_json: JsonOption = False,
) -> None:
    """`pipeline identify` on every session, one Dask task each; writes fleet.arrow."""
    _fleet("identify", dirs, scheduler, workers, out, as_json)


@commands.command("evaluate")
def fleet_evaluate(
    dirs: FleetDirs,
    scheduler: SchedulerOption = None,
    workers: FleetWorkers = None,
    out: FleetOut = None,
    as_json: JsonOption = False,
) -> None:
    """`pipeline evaluate` on every session (design vs signature gain); writes fleet.arrow."""
    _fleet("evaluate", dirs, scheduler, workers, out, as_json)


@commands.command("validate")
def fleet_validate(
    dirs: FleetDirs,
    scheduler: SchedulerOption = None,
    workers: FleetWorkers = None,
    out: FleetOut = None,
    as_json: JsonOption = False,
) -> None:
    """The validation (check) errors of every point session; sonic sessions have none."""
    _fleet("validate", dirs, scheduler, workers, out, as_json)


@commands.command("report")
def fleet_report(
    folder: Annotated[str, typer.Argument(help="Folder holding fleet.arrow.")],
    as_json: JsonOption = False,
) -> None:
    """Write FOLDER/fleet-report/fleet.md with figures from FOLDER/fleet.arrow."""
    from pipeline.fleet.report import write_fleet_report

    path = write_fleet_report(folder)
    if as_json:
        print_json({"report": str(path)})
        return
    typer.echo(f"wrote {path}")
