"""Freed memory handed back to the operating system between a run's steps (issue 45).

glibc's allocator keeps the pages a process freed for its next allocations. numpy arrays
below its mmap threshold (which rises to 32 MB once a larger block is freed) come from
that heap, so the chunked refinement's and registration's few-MB temporaries leave a heap
of freed pages that the next stage's work stacks on: a million-row identify's resident
memory stood at 1.7-2.5 GB between stages, of which ``malloc_trim`` returned 0.3-1.0 GB
(measured per stage, ``docs/scale.md``). :func:`return_freed` calls it after each stage;
on a C library without it (musl, macOS) it does nothing. Dask's workers trim the same way
(``distributed``'s memory manager)."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Callable


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None  # type: ignore[no-any-return]
    except (OSError, AttributeError):  # no glibc: nothing to trim
        return None


def return_freed() -> None:
    """Return the heap's free pages to the operating system (glibc's ``malloc_trim(0)``;
    nothing elsewhere). It frees nothing in use and takes ~1-10 ms."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
