"""The Dask client of ``pipeline fleet`` and ``pipeline montecarlo --scheduler``.

Default: a :class:`~distributed.LocalCluster` of worker processes (one thread each: the
stages hold the GIL in numpy / numba loops), started and stopped with the command.
``--scheduler tcp://HOST:PORT`` (or ``DASK_SCHEDULER_ADDRESS``) connects to an existing
cluster instead and leaves it running. Scheduling, placement and retries are Dask's.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from typing import Any

from pipeline.errors import ArmsigError

#: The environment variable Dask itself reads for its scheduler address.
SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
#: ``--scheduler local``: the embedded default, even when the environment names a scheduler.
LOCAL = "local"


def scheduler_address(scheduler: str | None) -> str | None:
    """The scheduler to connect to: ``scheduler``, else ``$DASK_SCHEDULER_ADDRESS``;
    None (or ``local``): start a local cluster."""
    address = scheduler or os.environ.get(SCHEDULER_ENV) or None
    return None if address == LOCAL else address


@contextlib.contextmanager
def dask_client(
    scheduler: str | None = None, workers: int | None = None, processes: bool = True
) -> Iterator[Any]:
    """A :class:`distributed.Client`: on ``scheduler`` (see :func:`scheduler_address`), else
    on a local cluster of ``workers`` (default: the machine's cores) started for the block."""
    import dask
    from distributed import Client, LocalCluster

    address = scheduler_address(scheduler)
    if address is not None:
        try:
            client = Client(address, timeout="10s")
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
    # The workers inherit this environment, as the process pool's workers do, without
    # Dask's one-thread caps of OpenBLAS / OpenMP / MKL: with them the Monte-Carlo noise
    # study took ~40 % more CPU time (docs/scale.md). Nannies read it when they start.
    with dask.config.set({"distributed.nanny.pre-spawn-environ": {}}):
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=processes,
            host="127.0.0.1",
            dashboard_address=":0",  # a free port: no clash with another cluster
        )
    with cluster, Client(cluster) as client:
        yield client
