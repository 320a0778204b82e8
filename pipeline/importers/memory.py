"""Whether an import of so many rows fits in this machine's memory (issue 45).

There is no fixed row limit: a file is refused, in one line, before anything is checked
or written, only when the peak memory of importing it or of identifying what it imports
(the larger) would exceed the memory available now (``MemAvailable`` of
``/proc/meminfo``, capped by the process's address-space limit). Each estimate is linear
in the rows, from peak resident memory measured on this project's 2-core machine for
UR10 pose sets of 100,000 to 1,000,000 rows (docs/import.md, "Size"); where the
available memory cannot be read, nothing is refused.
"""

from __future__ import annotations

import resource
from pathlib import Path

from pipeline.errors import ImportFileError

#: Peak resident memory (bytes) of ``pipeline identify`` (the report included) of an
#: imported pose set: the interpreter and its modules, plus per row. Measured (issue 45,
#: 2026-11-29, ``/usr/bin/time -v`` of the command, from no stage): 200,000 rows 0.87 GB,
#: 1,000,000 rows 3.13 GB (3.09 GB with ``--no-report``), since the model is chosen on a
#: subsample, stage tables are hashed as they are serialized and the report reads its
#: large tables by columns. Before: 4.62 GB at a million rows without the report (250 MB
#: + 4.4 kB a row), and 170 MB + 12.3 kB a row before the chain was evaluated a chunk at
#: a time.
BASE, PER_ROW = 300e6, 2_830.0
#: The import's own peak (bytes) since a pose set is written as ``/points/block`` (issue
#: 45, ``/usr/bin/time -v``, 2026-11-29): 100,000 rows 0.19 GB (polars' path 192 MB, the
#: ``csv`` path of a file with quotes or a blank line 186 MB), 1,000,000 rows 0.92 GB.
#: Before the blocks: 300,000 rows 1.89 GB, 1,000,000 rows 6.15 GB (60 MB + 6.1 kB a row).
IMPORT_BASE, IMPORT_PER_ROW = 110e6, 810.0
#: Headroom over the estimate (the measured sets are one layout; others differ a little).
HEADROOM = 1.25
MEMINFO = Path("/proc/meminfo")


def available_bytes() -> float | None:
    """Memory this process may still take (bytes): ``MemAvailable`` capped by
    ``RLIMIT_AS``; None when neither is known."""
    avail = None
    try:
        for line in MEMINFO.read_text(encoding="ascii").splitlines():
            if line.startswith("MemAvailable:"):
                avail = float(line.split()[1]) * 1024.0  # kB
    except (OSError, ValueError, IndexError):
        avail = None
    soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    if soft != resource.RLIM_INFINITY:
        avail = float(soft) if avail is None else min(avail, float(soft))
    return avail


def needed_bytes(rows: int) -> float:
    """The peak (bytes, with :data:`HEADROOM`) of importing ``rows`` rows or identifying
    them, the larger."""
    return HEADROOM * max(BASE + PER_ROW * rows, IMPORT_BASE + IMPORT_PER_ROW * rows)


def check_fits(name: str, rows: int) -> None:
    """Refuse ``rows`` rows of file ``name`` in one line when identifying them would not
    fit in the memory available now (module docstring)."""
    avail = available_bytes()
    need = needed_bytes(rows)
    if avail is None or need <= avail:
        return
    lines = ((BASE, PER_ROW), (IMPORT_BASE, IMPORT_PER_ROW))
    fit = max(min(int((avail / HEADROOM - b) / per) for b, per in lines), 0)
    raise ImportFileError(
        f"{name}: {rows:,} rows need about {need / 1e9:.1f} GB to import and identify, "
        f"{avail / 1e9:.1f} GB of memory is available",
        expected=f"at most ~{fit:,} rows on this machine now (docs/import.md, Size)",
        fix=f"free memory, or subsample the file (1 row in {-(-rows // max(fit, 1))} of "
        "each sweep), or import a part and choose the informative poses with "
        "`pipeline plan --from`",
    )
