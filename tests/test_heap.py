"""Memory a large run frees between its steps (issue 45): the heap's free pages handed
back (``pipeline.heap``), and columns built without a Python object per row."""

from __future__ import annotations

import ctypes.util
import sys

import numpy as np
import pyarrow as pa
import pytest

from pipeline.heap import _malloc_trim, return_freed
from pipeline.stages.joints import source_columns


def _resident_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or _malloc_trim() is None, reason="glibc's malloc_trim"
)
def test_freed_pages_below_a_live_block_go_back_to_the_system() -> None:
    """200 MB of 100 kB arrays freed under one still in use stay resident (glibc trims
    only the heap's top by itself) until :func:`return_freed`."""
    assert ctypes.util.find_library("c")
    blocks = [np.ones(12_500) for _ in range(2_000)]  # 100 kB each, below mmap's threshold
    pin = np.ones(12_500)
    del blocks
    before = _resident_bytes()
    return_freed()
    assert before - _resident_bytes() > 100e6
    assert pin.sum() == 12_500


@pytest.mark.parametrize("n", [1, 6])
def test_source_columns_are_the_files_and_lines_of_each_row_repeated(n: int) -> None:
    files = np.array(["a.csv", "a.csv", "", "b.csv", "a.csv", "", ""])
    lines = np.array([2, 3, 0, 2, 4, 0, -1])
    got = source_columns(files, lines, n)
    want_files = [None if f == "" else str(f) for f in files for _ in range(n)]
    want_lines = [None if v <= 0 else int(v) for v in lines for _ in range(n)]
    assert got["source_file"].type == pa.string()
    assert got["source_file"].to_pylist() == want_files
    assert got["source_line"].to_pylist() == want_lines
    assert source_columns(np.array([], str), np.array([], int))["source_file"].to_pylist() == []
