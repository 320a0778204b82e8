"""``pipeline fleet``: every session under the given folders is one Dask task.

The task (:func:`session_task`) calls the same importable function as the single-session
command (:func:`pipeline.identify.identify`, :func:`pipeline.evaluate.evaluate`)
and returns the session's row of ``fleet.arrow``. A refused session (an
:class:`~pipeline.errors.ArmsigError`) is an answer, not a failure: its row carries the
one-line error and the other sessions go on. Anything else (a bug, a killed worker) is
Dask's to retry (``retries``; a worker's death is rescheduled by the scheduler); what
still fails is reported the same way. The stage cache makes a rerun redo only what is
stale, and the session lock keeps two workers off one session.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from pipeline.errors import ArmsigError, SessionLockedError, one_line
from pipeline.fleet.row import empty_row, fleet_table, session_row

COMMANDS = ("identify", "evaluate", "validate")
TABLE_NAME = "fleet.arrow"
SCHEMA_NAME = "fleet"
SCHEMA_VERSION = "2"  # 2: robot_id (issue 43)
#: Reruns of a task that raised something other than a refusal (Dask's ``retries``).
RETRIES = 2


def session_task(command: str, session_dir: str) -> dict[str, Any]:
    """Run ``command`` on one session; its ``fleet.arrow`` row (``error`` set if refused).

    A :class:`~pipeline.errors.SessionLockedError` is raised, not returned: another run
    holds the session, so Dask's retry may find it free.
    """
    t0 = time.perf_counter()
    sdir = Path(session_dir)
    try:
        if command == "evaluate":
            from pipeline.evaluate import evaluate

            row = session_row(sdir, command, evaluate(sdir).summary)
        else:
            from pipeline.identify import identify

            identify(sdir)
            row = session_row(sdir, command)
    except SessionLockedError:
        raise
    except ArmsigError as exc:
        row = empty_row(session_dir, command)
        row["error"] = one_line(str(exc))
    row["task_s"] = time.perf_counter() - t0
    return row


def find_sessions(folders: list[str]) -> list[str]:
    """Every session folder (holding ``recording.mcap``) at or under ``folders``, sorted."""
    found: set[Path] = set()
    for f in folders:
        p = Path(f)
        if not p.is_dir():
            raise ArmsigError(f"{p}: no such folder", expected="session folders or their parents")
        if (p / "recording.mcap").is_file():
            found.add(p)
        else:
            found.update(r.parent for r in p.rglob("recording.mcap") if r.is_file())
    if not found:
        raise ArmsigError(
            f"no session under {' '.join(folders)}",
            expected="folders holding recording.mcap",
            fix="`pipeline simulate NAME` records one",
        )
    unique = {s.resolve(): s for s in sorted(found)}  # one task per session, however named
    return sorted(str(s) for s in unique.values())


@dataclass(frozen=True)
class FleetResult:
    rows: list[dict[str, Any]]
    table: Path
    wall_s: float

    @property
    def failed(self) -> list[dict[str, Any]]:
        """The sessions refused (their ``error``)."""
        return [r for r in self.rows if r["error"] is not None]

    @property
    def verdict_failed(self) -> list[dict[str, Any]]:
        """The sessions identified whose verdict is FAIL (docs/verdict.md)."""
        return [r for r in self.rows if r["error"] is None and r["verdict"] == "FAIL"]


def run_fleet(
    command: str,
    folders: list[str],
    client: Any,
    out: str | Path,
    progress: TextIO | None = sys.stderr,
) -> FleetResult:
    """Run ``command`` on every session under ``folders`` on the Dask ``client``; write
    ``out/fleet.arrow`` (one row per session) and return the rows."""
    from distributed import as_completed

    from pipeline.atomic import check_writable
    from pipeline.progress import Progress

    if command not in COMMANDS:
        raise ArmsigError(f"unknown fleet command {command!r}", expected=", ".join(COMMANDS))
    sessions = find_sessions(folders)
    out_dir = check_writable(out, "--out", folder=True)
    t0 = time.perf_counter()
    futures = client.map(
        session_task, [command] * len(sessions), sessions, retries=RETRIES, pure=False
    )
    by_key = {f.key: s for f, s in zip(futures, sessions, strict=True)}
    bar = Progress(f"fleet {command}", len(sessions), progress, unit="sessions")
    rows = []
    for f in as_completed(futures):
        if f.status == "finished":
            rows.append(f.result())
        else:  # raised on every try (or its workers kept dying): reported, not raised
            exc = f.exception()
            row = empty_row(by_key[f.key], command)
            row["error"] = one_line(
                str(exc) if isinstance(exc, ArmsigError) else f"{type(exc).__name__}: {exc}"
            )
            rows.append(row)
        bar.step()
    wall = time.perf_counter() - t0
    path = write_fleet(out_dir / TABLE_NAME, rows, command, wall)
    return FleetResult(sorted(rows, key=lambda r: r["session"]), path, wall)


def fleet(
    command: str,
    folders: list[str],
    scheduler: str | None = None,
    workers: int | None = None,
    out: str | Path | None = None,
    progress: TextIO | None = sys.stderr,
) -> FleetResult:
    """:func:`run_fleet` on the Dask ``scheduler`` (tcp://HOST:PORT; None: the
    environment's, else a local cluster of ``workers`` for this call, sharing the cores);
    ``out``: the folder of fleet.arrow (default: the first of ``folders``). The sessions
    and ``out`` are refused before a cluster starts."""
    from pipeline.atomic import check_writable
    from pipeline.fleet.engine import FLEET_PRELOAD, dask_client

    sessions = find_sessions(folders)
    folder = check_writable(out or folders[0], "--out", folder=True)
    with dask_client(scheduler, workers, preload=FLEET_PRELOAD, share_cores=True,
                     progress=progress) as client:  # fmt: skip
        return run_fleet(command, sessions, client, folder, progress=progress)


def write_fleet(path: Path, rows: list[dict[str, Any]], command: str, wall_s: float) -> Path:
    """``fleet.arrow`` written atomically, with its schema name and version and provenance."""
    from pipeline import __version__
    from pipeline.stages.tables import write_table

    table = fleet_table(rows)
    meta = {b"schema_name": SCHEMA_NAME.encode(), b"schema_version": SCHEMA_VERSION.encode()}
    prov = {
        "command": command,
        "sessions": len(rows),
        "failed": sum(r["error"] is not None for r in rows),
        "verdict_fail": sum(r["error"] is None and r["verdict"] == "FAIL" for r in rows),
        "wall_s": round(wall_s, 3),
        "package_version": __version__,
    }
    write_table(path, table.replace_schema_metadata(meta), prov)
    return path
