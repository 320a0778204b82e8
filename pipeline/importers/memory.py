"""Whether an import of so many rows fits in this machine's memory (issue 45).

There is no fixed row limit: a file is refused, in one line, before anything is checked
or written, only when the peak memory of identifying what it imports (more than the
import's own) would exceed the memory available now (``MemAvailable`` of ``/proc/meminfo``,
capped by the process's address-space limit). The estimate is linear in the rows, from
peak resident memory measured on this project's 2-core machine for UR10 pose sets of
20,000 to 100,000 rows (docs/import.md, "Size"); where the available memory
cannot be read, nothing is refused.
"""

from __future__ import annotations

import resource
from pathlib import Path

from pipeline.errors import ImportFileError

#: Peak resident memory (bytes) of ``pipeline identify --no-report`` of an imported pose
#: set: the interpreter and its modules, plus per row. Measured (peak RSS): 20,000 rows
#: 412 MB, 50,000 rows 779 MB. The import itself peaks lower (20,000 rows 174 MB, 50,000
#: 355 MB, 100,000 628 MB: 60 MB + 5.7 kB a row), so identify's peak decides.
BASE, PER_ROW = 170e6, 12_300.0
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
    """The peak (bytes, with :data:`HEADROOM`) of identifying ``rows`` imported rows."""
    return HEADROOM * (BASE + PER_ROW * rows)


def check_fits(name: str, rows: int) -> None:
    """Refuse ``rows`` rows of file ``name`` in one line when identifying them would not
    fit in the memory available now (module docstring)."""
    avail = available_bytes()
    need = needed_bytes(rows)
    if avail is None or need <= avail:
        return
    fit = max(int((avail / HEADROOM - BASE) / PER_ROW), 0)
    raise ImportFileError(
        f"{name}: {rows:,} rows need about {need / 1e9:.1f} GB to identify, "
        f"{avail / 1e9:.1f} GB of memory is available",
        expected=f"at most ~{fit:,} rows on this machine now (docs/import.md, Size)",
        fix=f"free memory, or subsample the file (1 row in {-(-rows // max(fit, 1))} of "
        "each sweep), or import a part and choose the informative poses with "
        "`pipeline plan --from`",
    )
