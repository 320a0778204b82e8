"""``pipeline fleet`` on Dask (issue 17): one task per session on a LocalCluster of 2 workers
on loopback. The byte-identity and failure tests use thread workers (``processes=False``:
no worker start-up or imports per test); the killed-worker test uses worker processes."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import threading
import time
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.fleet.engine import WORKER_START_TIMEOUT_S
from pipeline.fleet.run import TABLE_NAME, find_sessions, run_fleet
from pipeline.identify import identify
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.stages.tables import read_provenance, read_table

distributed = pytest.importorskip("distributed")

#: 6 sonic sessions and 2 tracker sessions with validation configurations.
N_SESSIONS = 8


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Eight small simulated sessions (recordings only) under one folder."""
    root = tmp_path_factory.mktemp("fleet")
    for i in range(N_SESSIONS):
        tracker = i >= 6
        opts = SimulationOptions(
            seed=i + 1, points=12, repeats=2,
            sensor="tracker" if tracker else "sonic", check=8 if tracker else 0,
        )  # fmt: skip
        simulate_session(root / f"r{i}", opts)
    return root


@pytest.fixture(scope="module")
def threads():
    """A loopback LocalCluster of 2 single-thread workers in this process, and its client."""
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
            host="127.0.0.1", dashboard_address=":0",
        ) as cluster,
        distributed.Client(cluster) as client,
    ):  # fmt: skip
        yield client


def _copy(recorded: Path, dest: Path) -> Path:
    shutil.copytree(recorded, dest)
    return dest


def _without_time(provenance: dict) -> dict:
    """Stage provenance without its creation time (the one field that differs)."""
    return {k: v for k, v in provenance.items() if k != "created"}


def _signature_without_time(path: Path) -> bytes:
    """signature.json's bytes without its creation time and the self-digest covering it."""
    doc = json.loads(path.read_text())
    del doc["provenance"]["created"], doc["sha256"]
    return json.dumps(doc, indent=1).encode()


def test_fleet_identify_equals_sequential_identify(recorded: Path, tmp_path: Path, threads) -> None:
    """The same stage tables and signature.json, byte for byte, up to the creation times
    that stage provenance and signature.json record (to the second)."""
    fleet, seq = _copy(recorded, tmp_path / "fleet"), _copy(recorded, tmp_path / "seq")
    r = run_fleet("identify", [str(fleet)], threads, fleet, progress=None)
    assert not r.failed and len(r.rows) == N_SESSIONS
    for s in sorted(seq.iterdir()):
        identify(s)
        f = fleet / s.name
        stages = sorted(p.name for p in (s / "stages").glob("*.arrow"))
        assert stages == sorted(p.name for p in (f / "stages").glob("*.arrow"))
        for name in stages:  # every stage table: the same data, the same provenance
            a, b = read_table(f / "stages" / name), read_table(s / "stages" / name)
            assert a.equals(b, check_metadata=False)
            assert _without_time(read_provenance(f / "stages" / name)) == _without_time(
                read_provenance(s / "stages" / name)
            )
        assert _signature_without_time(f / "signature.json") == _signature_without_time(
            s / "signature.json"
        )
    df = pl.scan_ipc(fleet / TABLE_NAME).collect()
    assert df.height == N_SESSIONS and df["error"].null_count() == N_SESSIONS
    assert df.filter(pl.col("sensor") == "points")["check_points"].to_list() == [8, 8]
    # A rerun redoes nothing: every stage file and signature stays as it is.
    before = {p: p.stat().st_mtime_ns for p in fleet.rglob("*") if p.is_file()}
    run_fleet("identify", [str(fleet)], threads, fleet, progress=None)
    after = {p: p.stat().st_mtime_ns for p in before if p.name != TABLE_NAME}
    assert after == {p: t for p, t in before.items() if p.name != TABLE_NAME}


def test_a_corrupted_session_is_reported_and_the_others_finish(
    recorded: Path, tmp_path: Path, threads
) -> None:
    fleet = _copy(recorded, tmp_path / "fleet")
    rec = fleet / "r3" / "recording.mcap"
    rec.write_bytes(rec.read_bytes()[: rec.stat().st_size // 2])  # truncated
    address = threads.scheduler.address
    res = CliRunner().invoke(app, ["fleet", "identify", str(fleet), "--scheduler", address])
    assert res.exit_code == 1, res.output
    df = pl.scan_ipc(fleet / TABLE_NAME).collect()
    assert df.height == N_SESSIONS
    bad = df.filter(pl.col("error").is_not_null())
    assert bad["session"].to_list() == [str(fleet / "r3")]
    assert "\n" not in bad["error"][0] and "recording" in bad["error"][0]
    assert bad["signature_sha256"][0] is None
    assert df.filter(pl.col("error").is_null()).height == N_SESSIONS - 1
    assert f"FAILED {fleet / 'r3'}:" in res.output
    assert re.search(rf"^  (PASS|CHECK|FAIL) +{re.escape(str(fleet / 'r0'))}:", res.output, re.M)
    assert all((fleet / f"r{i}" / "signature.json").is_file() for i in range(8) if i != 3)


def test_fleet_validate_says_what_sonic_sessions_lack(recorded: Path, tmp_path: Path, threads):
    fleet = tmp_path / "fleet"
    for name in ("r0", "r6"):
        shutil.copytree(recorded / name, fleet / name)
    r = run_fleet("validate", [str(fleet)], threads, fleet, progress=None)
    by = {Path(row["session"]).name: row for row in r.rows}
    assert by["r6"]["check_rms_cm"] < 0.05 and by["r6"]["check_points"] == 8
    assert by["r0"]["check_rms_cm"] is None
    assert any("no validation numbers" in w for w in by["r0"]["warnings"])
    md = CliRunner().invoke(app, ["fleet", "report", str(fleet)])
    assert md.exit_code == 0, md.output
    text = (fleet / "fleet-report" / "fleet.md").read_text()
    assert "2 sessions, 0 failed" in text and "| puma560 |" in text
    assert all((fleet / "fleet-report" / f).is_file() for f in ("gain.png", "drift.png"))


def test_fleet_report_marks_a_signature_gone_stale(recorded: Path, tmp_path: Path, threads):
    """Issue 32: the report read signatures by their digest only, so a session whose
    recording changed after ``fleet identify`` still had its drift computed from the old
    signature. It is now checked as every consumer checks it, and marked."""
    from pipeline.fleet.report import load_rows, write_fleet_report

    fleet = tmp_path / "fleet"
    for i in (6, 7):  # r6, r7 measured as one arm (issue 43: drift is per robot id)
        opts = SimulationOptions(seed=i + 1, points=12, repeats=2, sensor="tracker", check=8,
                                 robot_id="P-1")  # fmt: skip
        simulate_session(fleet / f"r{i}", opts)
    run_fleet("identify", [str(fleet)], threads, fleet, progress=None)
    text = write_fleet_report(fleet).read_text()
    # The later of the two in identification order (the workers may finish r7 first).
    earlier, later = (Path(r["session"]) for r in sorted(
        load_rows(fleet), key=lambda r: (r["identified_utc"], r["session"])))  # fmt: skip
    assert re.search(rf"\| P-1 \| .*{later.name} \| \d", text), text  # a drift value
    shutil.copyfile(earlier / "recording.mcap", later / "recording.mcap")
    text = write_fleet_report(fleet).read_text()
    assert "2 sessions, 0 failed, 0 with verdict FAIL, 1 no longer as fleet.arrow" in text
    drift_row = next(line for line in text.splitlines() if line.startswith("| P-1 |"))
    assert "stale: identified from another recording.mcap" in drift_row, drift_row


def test_find_sessions_refuses_an_empty_folder(tmp_path: Path) -> None:
    from pipeline.errors import ArmsigError

    with pytest.raises(ArmsigError, match="no session under"):
        find_sessions([str(tmp_path)])


def test_killing_a_worker_mid_run_still_completes_every_session(
    recorded: Path, tmp_path: Path
) -> None:
    fleet = tmp_path / "fleet"
    for i in range(4):
        shutil.copytree(recorded / f"r{i}", fleet / f"r{i}")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
            dashboard_address=":0",
        ) as cluster,
        distributed.Client(cluster) as client,
    ):  # fmt: skip
        pids = client.run(os.getpid)
        killed: list[str] = []

        def kill_a_busy_worker() -> None:
            deadline = time.monotonic() + WORKER_START_TIMEOUT_S
            while time.monotonic() < deadline:
                busy = [w for w, tasks in client.processing().items() if tasks]
                if busy:
                    time.sleep(0.5)  # inside the task: imports, stages
                    os.kill(pids[busy[0]], signal.SIGKILL)
                    killed.append(busy[0])
                    return
                time.sleep(0.05)

        killer = threading.Thread(target=kill_a_busy_worker)
        killer.start()
        r = run_fleet("identify", [str(fleet)], client, fleet, progress=None)
        killer.join()
    assert killed, "no worker was busy"
    assert [row["error"] for row in r.rows] == [None] * 4
    assert all((fleet / f"r{i}" / "signature.json").is_file() for i in range(4))


def _toy(value: float, seeds: list) -> np.ndarray:
    """Index 0 = value·z, index 1 = value·z², z standard normal per robot."""
    z = np.array([np.random.default_rng(s).standard_normal() for s in seeds])
    return np.stack([value * z, value * z**2], axis=-1)


def test_montecarlo_on_dask_is_bit_identical_for_any_workers_and_batch(threads) -> None:
    from pipeline.montecarlo.engine import Study, run_study

    toy = Study("toy", "toy", "s_cm", "cm", (0.5, 2.0), _toy, ("a_cm", "b_cm"),
                ("cm", "cm"), (True, True), batch=40)  # fmt: skip
    local = run_study(toy, robots=301, seed=5, workers=1, progress=None)
    on_dask = run_study(toy, robots=301, seed=5, progress=None, client=threads)
    other_batch = run_study(toy, robots=301, seed=5, progress=None, client=threads, batch=77)
    assert np.array_equal(local.values, on_dask.values)
    assert np.array_equal(local.values, other_batch.values)


def test_montecarlo_scheduler_option_gives_the_same_tables(tmp_path: Path, threads) -> None:
    runner = CliRunner()
    base = ["montecarlo", "--study", "machining", "--robots", "6"]
    assert runner.invoke(app, [*base, "--out", str(tmp_path / "a")]).exit_code == 0
    address = threads.scheduler.address
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "b"), "--scheduler", address])
    assert res.exit_code == 0, res.output
    a, b = (read_table(tmp_path / d / "machining" / "indices.arrow") for d in ("a", "b"))
    assert a.equals(b, check_metadata=False)


def test_scheduler_address_from_option_environment_or_local(monkeypatch) -> None:
    from pipeline.fleet.engine import SCHEDULER_ENV, scheduler_address

    monkeypatch.delenv(SCHEDULER_ENV, raising=False)
    assert scheduler_address(None) is None  # a local cluster
    monkeypatch.setenv(SCHEDULER_ENV, "tcp://10.0.0.1:8786")
    assert scheduler_address(None) == "tcp://10.0.0.1:8786"
    assert scheduler_address("tcp://h:1") == "tcp://h:1"
    assert scheduler_address("local") is None


@pytest.mark.parametrize("address", ["not a url", "http://x", "tcp://[bad"])
def test_a_scheduler_that_is_not_an_address_is_one_line(tmp_path: Path, address: str) -> None:
    """Issue 32: ``--scheduler 'not a url'`` ended in exit 70 (distributed's ValueError)."""
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "recording.mcap").write_bytes(b"")
    res = CliRunner().invoke(app, ["fleet", "identify", str(tmp_path), "--scheduler", address])
    assert res.exit_code == 1, res.output
    assert res.stderr.startswith("error: ") and len(res.stderr.splitlines()) == 1, res.stderr
    assert f"{address!r} is not a Dask scheduler address" in res.stderr


def test_fleet_evaluate_gives_the_measured_gain(recorded: Path, tmp_path: Path, threads) -> None:
    fleet = tmp_path / "fleet"
    shutil.copytree(recorded / "r0", fleet / "r0")
    (row,) = run_fleet("evaluate", [str(fleet)], threads, fleet, progress=None).rows
    assert row["error"] is None and row["gain_evaluation"] > 1.0
    assert (fleet / "r0" / "evaluation.mcap").is_file()


def _worker_state(dask_worker) -> tuple[bool, bool]:
    """(the identification imported, the statistical profiler scheduled) in a worker."""
    import sys

    return "pipeline.identify" in sys.modules, "profile" in dask_worker.periodic_callbacks


def test_fleet_local_workers_start_with_the_pipeline_imported_and_no_profiler() -> None:
    """The engine's local cluster for `pipeline fleet`: each worker imports the stages as it
    starts (preload), not in its first task, and runs no statistical profiler (it took
    ~11 % of a worker's CPU on identify, docs/scale.md). A replaced worker does the same."""
    from pipeline.fleet.engine import FLEET_PRELOAD, dask_client

    with dask_client(None, workers=1, preload=FLEET_PRELOAD) as client:
        assert list(client.run(_worker_state).values()) == [(True, False)]
        client.restart(timeout=WORKER_START_TIMEOUT_S)
        assert list(client.run(_worker_state).values()) == [(True, False)]


def _blas_threads() -> str | None:
    import os

    return os.environ.get("OPENBLAS_NUM_THREADS")


def test_fleet_local_workers_share_the_cores_for_blas() -> None:
    """With ``share_cores`` (pipeline fleet) each local worker's BLAS gets its share of the
    cores: 2 workers with one OpenBLAS thread per core each oversubscribed 2 cores and took
    202 s of worker CPU for 20 identifications that take 109 s in one process. Without it
    (the Monte-Carlo study) the workers inherit this process's environment."""
    import os

    from pipeline.fleet.engine import dask_client, shared_cores_environ

    share = str(max(1, (os.cpu_count() or 1) // 2))
    assert shared_cores_environ(2)["OPENBLAS_NUM_THREADS"] == share
    with dask_client(None, workers=2, share_cores=True) as client:
        assert set(client.run(_blas_threads).values()) == {share}
        client.restart(timeout=WORKER_START_TIMEOUT_S)
        assert set(client.run(_blas_threads).values()) == {share}
    with dask_client(None, workers=1) as client:
        assert set(client.run(_blas_threads).values()) == {_blas_threads()}
