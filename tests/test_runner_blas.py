"""Stages compute with one BLAS thread: the same bits whatever the caller's BLAS threads."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from pipeline.identify import identify
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.stages.runner import committed_hashes


def _hashes(recording: Path, folder: Path, threads: int) -> dict[str, str | None]:
    folder.mkdir()
    shutil.copy(recording, folder / "recording.mcap")
    with threadpool_limits(threads, user_api="blas"):
        identify(folder, report=False)
    return committed_hashes(folder)


@pytest.mark.skipif(
    max((i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"), default=1) < 2,
    reason="BLAS has one thread here: nothing to compare",
)
def test_stage_hashes_do_not_depend_on_the_callers_blas_threads(tmp_path: Path) -> None:
    # Before the runner pinned one thread, this session's refine, chain and every later
    # table hashed differently with 2 BLAS threads than with 1.
    simulate_session(tmp_path / "sim", SimulationOptions(seed=7, noise_factor=4.6))
    recording = tmp_path / "sim" / "recording.mcap"  # one recording, identified twice
    one, two = _hashes(recording, tmp_path / "one", 1), _hashes(recording, tmp_path / "two", 2)
    assert one == two
    assert one["refine"] is not None
