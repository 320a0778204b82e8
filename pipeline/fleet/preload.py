"""Dask worker preload of the local cluster (``LocalCluster(preload=[__name__])``).

Imports what a fleet task imports on first use, so that each worker process does it while
the cluster starts rather than inside its first task: the stage modules of every sensor
and of ``evaluate``, the report (matplotlib), and the libraries the stages import lazily
(a warm single-session run does not need them, a fresh worker does). Missing one here
costs time, not correctness: the task imports it.
"""

from __future__ import annotations

import importlib

from pipeline.stages.catalog import (
    EVALUATE_STAGE_MODULES,
    POINT_STAGE_MODULES,
    STAGE_MODULES,
    stages,
)

#: Imported lazily by the stages, the report and evaluate (the first task's ~0.5-1 s CPU).
MODULES = (
    "pipeline.fleet.run",
    "pipeline.identify",
    "pipeline.evaluate",
    "pipeline.report.identification",
    "matplotlib.figure",
    "matplotlib.backends.backend_agg",
    "mcap.stream_reader",
    "pyarrow.compute",
    "scipy.optimize",
    "scipy.spatial.transform",
    "scipy.special",
)

for _m in MODULES:
    importlib.import_module(_m)
stages(STAGE_MODULES + POINT_STAGE_MODULES + EVALUATE_STAGE_MODULES)
