"""The Dask client of ``pipeline fleet`` and ``pipeline montecarlo --scheduler``.

Default: a :class:`~distributed.LocalCluster` of worker processes (one thread each: the
stages hold the GIL in numpy / numba loops), started and stopped with the command.
``--scheduler tcp://HOST:PORT`` (or ``DASK_SCHEDULER_ADDRESS``) connects to an existing
cluster instead and leaves it running. Scheduling, placement and retries are Dask's.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from typing import Any, TextIO

from pipeline.errors import ArmsigError
from pipeline.quiet import debugging, quiet

#: The environment variable Dask itself reads for its scheduler address.
SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
#: ``--scheduler local``: the embedded default, even when the environment names a scheduler.
LOCAL = "local"
#: ``preload`` of a fleet's local workers: the modules a session's task imports.
FLEET_PRELOAD = ("pipeline.fleet.preload",)
#: ``preload`` of every local cluster of worker processes: no other package's warnings or
#: log records from the workers (they share the command's stderr), unless ARMSIG_DEBUG=1.
QUIET_PRELOAD = ("pipeline.fleet.quiet_worker",)
#: Dask configuration of the local cluster's workers (docs/scale.md has the numbers):
#: - ``pre-spawn-environ`` empty: the workers inherit this environment, as the process
#:   pool's workers do, without Dask's one-thread caps of OpenBLAS / OpenMP / MKL (with
#:   them the Monte-Carlo noise study took ~40 % more CPU time).
#: - no statistical profiler: it samples the task thread's Python stack every 10 ms, under
#:   the GIL: 4-22 % (mean 11 %) of a worker's CPU on identify. Only the dashboard's
#:   profile page reads it.
LOCAL_CONFIG = {
    "distributed.nanny.pre-spawn-environ": {},
    "distributed.worker.profile.enabled": False,
}
#: How long local workers may take to start, and a restarted one to return (s). Idle, a
#: worker with the fleet preload starts in ~2-4 s on 2 cores; loaded (two busy processes
#: per core and other users' runs, load 8-14) it took over 60 s (Dask's 60 s wait in the
#: tests: "Only 0/1 workers arrived after 60") and a restart over 120 s (Dask's default).
#: Ten minutes leaves a busy workstation time; a worker that is still missing then is
#: refused in one line (docs/scale.md).
WORKER_START_TIMEOUT_S = 600.0
#: Thread pools of the numerical libraries, capped per worker by ``share_cores``.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def shared_cores_environ(workers: int) -> dict[str, str]:
    """The environment that gives each of ``workers`` local workers its share of the
    cores for BLAS. OpenBLAS's default of one thread per core in every worker once
    oversubscribed 2 cores with 4 spinning threads (fleet identify of 20 sessions: 202 s
    of worker CPU against 109 s sequentially, 0.69×). The stages now compute with one BLAS
    thread themselves (:func:`pipeline.stages.runner.one_blas_thread`); this caps the rest
    of a worker's work (reports, audits)."""
    share = str(max(1, (os.cpu_count() or 1) // max(workers, 1)))
    return dict.fromkeys(BLAS_THREAD_VARIABLES, share)


def scheduler_address(scheduler: str | None) -> str | None:
    """The scheduler to connect to: ``scheduler``, else ``$DASK_SCHEDULER_ADDRESS``;
    None (or ``local``): start a local cluster."""
    address = scheduler or os.environ.get(SCHEDULER_ENV) or None
    return None if address == LOCAL else address


@contextlib.contextmanager
def dask_client(
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    preload: tuple[str, ...] = (),
    share_cores: bool = False,
    progress: TextIO | None = None,
) -> Iterator[Any]:
    """A :class:`distributed.Client`: on ``scheduler`` (see :func:`scheduler_address`), else
    on a local cluster of ``workers`` (default: the machine's cores) started for the block,
    each worker importing the modules ``preload`` (e.g. :data:`FLEET_PRELOAD`) as it starts
    and, with ``share_cores``, its share of the cores for BLAS (:func:`shared_cores_environ`).
    The block starts once every local worker has (up to :data:`WORKER_START_TIMEOUT_S`;
    ``progress``: where to say what it waits for). An existing cluster is used as it is
    configured. Inside the block, and in the local workers, Dask logs nothing and other
    packages warn nothing (:mod:`pipeline.quiet`)."""
    import distributed  # noqa: F401  (it sets its loggers' levels on import; quiet() after)

    with quiet():  # Dask's log records and warnings (the workers': QUIET_PRELOAD)
        with _client(scheduler, workers, processes, preload, share_cores, progress) as client:
            yield client


@contextlib.contextmanager
def _client(
    scheduler: str | None,
    workers: int | None,
    processes: bool,
    preload: tuple[str, ...],
    share_cores: bool,
    progress: TextIO | None,
) -> Iterator[Any]:
    import dask
    from distributed import Client, LocalCluster

    address = scheduler_address(scheduler)
    if address is not None:
        try:
            client = Client(address, timeout="10s")
        except ValueError as exc:  # distributed's parse of the address ("not a url")
            raise ArmsigError(
                f"{address!r} is not a Dask scheduler address",
                expected="tcp://HOST:PORT (or local)",
                got=str(exc),
                fix="--scheduler tcp://HOST:PORT, or drop --scheduler for a local cluster",
            ) from exc
        except OSError as exc:
            raise ArmsigError(
                f"cannot reach the Dask scheduler {address}",
                got=str(exc),
                fix="start it (`dask scheduler`) or drop --scheduler for a local cluster",
            ) from exc
        with client:
            yield client
        return
    n = workers or os.cpu_count() or 1
    # Thread workers read the config as they are created; a nanny keeps its ``config``
    # for the worker processes it starts and restarts (dask.config.set is undone on exit).
    config = dict(LOCAL_CONFIG)
    if share_cores:
        config["distributed.nanny.pre-spawn-environ"] = shared_cores_environ(n)
    nanny = {"config": config} if processes else {}
    if progress is not None:
        print(f"starting {n} local Dask worker{'s' if n > 1 else ''} (waiting up to "
              f"{WORKER_START_TIMEOUT_S:.0f} s: a busy machine starts them slowly)",
              file=progress, flush=True)  # fmt: skip
    t0 = time.monotonic()
    with dask.config.set(config):
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=processes,
            host="127.0.0.1",
            dashboard_address=":0",  # a free port: no clash with another cluster
            preload=[*preload, *(QUIET_PRELOAD if processes and not debugging() else ())],
            **nanny,
        )
    with cluster, Client(cluster) as client:
        left = max(WORKER_START_TIMEOUT_S - (time.monotonic() - t0), 1.0)
        try:
            client.wait_for_workers(n, timeout=left)
        except TimeoutError as exc:  # distributed's WorkerStartTimeoutError
            raise ArmsigError(
                f"only {len(client.scheduler_info()['workers'])} of {n} local Dask workers "
                f"started within {WORKER_START_TIMEOUT_S:.0f} s",
                fix="try --workers 1, or again when the machine is less busy, or "
                "--scheduler tcp://HOST:PORT of a running cluster",
            ) from exc
        yield client
