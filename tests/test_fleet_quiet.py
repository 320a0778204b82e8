"""No Dask log lines or other packages' warnings on the terminal (issue 30 item 6, issue 32):
``fleet identify`` printed 25 lines of ``distributed.worker - ERROR - Compute Failed`` with
traceback text for one failing session (3 tries). The worker processes write to the
command's own stderr, so these tests run the command as a process and read its stderr."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from pipeline.quiet import DEBUG_ENV
from pipeline.rig.simulate import SimulationOptions, simulate_session

pytest.importorskip("distributed")

#: What a Dask or tornado log record starts with (distributed's log format).
DASK_LINE = ("distributed.", "tornado.", " - distributed", " - tornado")


def _run(args: list[str], debug: bool = False, timeout: float = 900) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != DEBUG_ENV}
    if debug:
        env[DEBUG_ENV] = "1"
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, env=env, timeout=timeout
    )


def _assert_quiet(stderr: str) -> None:
    assert "Traceback" not in stderr and "Compute Failed" not in stderr, stderr
    for line in stderr.splitlines():
        assert not any(m in line for m in DASK_LINE), line


def test_fleet_identify_failing_sessions_are_one_line_each(tmp_path: Path) -> None:
    """One good session, one truncated recording (refused) and one whose stage folder is
    a file (an OSError inside the task, retried by Dask): a line each, nothing else."""
    root = tmp_path / "fleet"
    for name in ("good", "truncated", "blocked"):
        simulate_session(root / name, SimulationOptions(seed=1, points=12, repeats=2))
    rec = root / "truncated" / "recording.mcap"
    rec.write_bytes(rec.read_bytes()[: rec.stat().st_size // 2])
    (root / "blocked" / "stages").write_text("not a folder\n")
    args = ["-m", "pipeline", "fleet", "identify", str(root), "--scheduler", "local"]
    r = _run([*args, "--workers", "1", "--json"])
    assert r.returncode == 1, r.stderr
    _assert_quiet(r.stderr)
    rows = {Path(s["session"]).name: s for s in json.loads(r.stdout)["sessions"]}
    assert rows["good"]["error"] is None and rows["good"]["verdict"] in ("PASS", "CHECK")
    for name in ("truncated", "blocked"):
        assert rows[name]["error"] and "\n" not in rows[name]["error"]
    err = r.stderr.splitlines()
    assert err.pop(0).startswith("starting 1 local Dask worker (waiting up to 600 s")
    assert err[0].startswith("fleet identify ") and "3/3 sessions" in err[0]
    assert err[-1].startswith("error: 2 of 3 sessions failed")
    assert all(line.startswith("warning: ") for line in err[1:-1]), err
    text = _run([*args, "--workers", "1"])  # the text output: a FAILED line per session
    failed = [ln for ln in text.stdout.splitlines() if ln.startswith("  FAILED ")]
    assert [ln.split(":")[0] for ln in failed] == [
        f"  FAILED {root / 'blocked'}",
        f"  FAILED {root / 'truncated'}",
    ]
    _assert_quiet(text.stderr)


#: Tasks on a local cluster of worker processes: a third-party warning, numpy's
#: RuntimeWarning and an exception in a task, then a worker that dies.
SCRIPT = textwrap.dedent(
    """
    import os, warnings
    from pipeline.fleet.engine import WORKER_START_TIMEOUT_S, dask_client

    def fail(x):
        warnings.warn("a warning of another package", UserWarning)
        import numpy as np
        np.log(np.zeros(1))
        raise ValueError("boom")

    def die(x):
        os._exit(1)

    if __name__ == "__main__":
        with dask_client(None, workers=1) as client:
            for task in (fail, die):
                try:
                    client.submit(task, 1, pure=False, retries=0).result()
                except Exception as exc:
                    print(type(exc).__name__)
            # the nanny's restart, before closing
            client.wait_for_workers(1, timeout=WORKER_START_TIMEOUT_S)
    """
)


def test_local_workers_log_and_warn_nothing_unless_debugging(tmp_path: Path) -> None:
    script = tmp_path / "tasks.py"
    script.write_text(SCRIPT)
    quiet = _run([str(script)])
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stdout.split() == ["ValueError", "KilledWorker"]
    assert quiet.stderr == ""
    debug = _run([str(script)], debug=True)  # ARMSIG_DEBUG=1: as Dask and Python decide
    assert debug.returncode == 0 and debug.stdout == quiet.stdout
    assert "a warning of another package" in debug.stderr
    assert any(m in debug.stderr for m in DASK_LINE)


def test_fleet_without_its_command_says_which_it_takes() -> None:
    """Issue 44: ``pipeline fleet`` printed its help, then "error: ; try: ..."."""
    from typer.testing import CliRunner

    from pipeline.cli import EXIT_USAGE, app

    r = CliRunner().invoke(app, ["fleet"])
    assert r.exit_code == EXIT_USAGE, r.output
    assert r.stderr == (
        "error: Missing command; expected one of identify, evaluate, validate, report; "
        "try: pipeline fleet --help\n"
    )


def test_local_workers_are_awaited_saying_so_and_a_missing_one_is_one_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Issue 44: on a loaded machine (load 8-14 on 2 cores) local workers took over the 60 s
    that a test waited ("Only 0/1 workers arrived after 60"), and a restarted one over
    Dask's 120 s. The block starts once every worker has, up to WORKER_START_TIMEOUT_S,
    and says what it waits for; a worker still missing then is one line."""
    import io

    import distributed
    from distributed.exceptions import WorkerStartTimeoutError

    from pipeline.errors import ArmsigError
    from pipeline.fleet.engine import WORKER_START_TIMEOUT_S, dask_client

    assert WORKER_START_TIMEOUT_S >= 600
    said = io.StringIO()
    with dask_client(None, workers=1, progress=said) as client:
        assert len(client.scheduler_info()["workers"]) == 1  # there when the block starts
    assert said.getvalue() == (
        "starting 1 local Dask worker (waiting up to 600 s: a busy machine starts them slowly)\n"
    )

    def late(self, n_workers, timeout=None):  # type: ignore[no-untyped-def]
        raise WorkerStartTimeoutError(0, n_workers, timeout)

    monkeypatch.setattr(distributed.Client, "wait_for_workers", late)
    with pytest.raises(ArmsigError) as exc, dask_client(None, workers=1):
        pass
    assert "of 1 local Dask workers started within 600 s" in str(exc.value)
    assert "try: try --workers 1" in str(exc.value) and "\n" not in str(exc.value)
