"""The ``refine`` Monte-Carlo study (issue 15): whole simulate + identify sessions per robot.

Small plan for speed (tests only): ``refine_all`` bound to N_i = 12 points and N_avg = 5
cycles with :func:`functools.partial` (picklable, so worker processes and Dask workers run
the same small plan); the registered study uses the default plan (100 points, 10 cycles).
"""

from __future__ import annotations

import re
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import polars as pl
import pytest
from threadpoolctl import threadpool_limits

from pipeline.montecarlo import output, refine_study, report
from pipeline.montecarlo.engine import StudyResult, run_study
from pipeline.montecarlo.studies import LATER, STUDY_NAMES, get_study

ROBOTS = 2


def _small():
    st = get_study("refine")
    return replace(st, evaluate_all=partial(refine_study.refine_all, points=12, repeats=5))


@pytest.fixture(scope="module")
def in_process() -> StudyResult:
    with threadpool_limits(2, user_api="blas"):  # the study pins its own: 1 thread
        return run_study(_small(), robots=ROBOTS, seed=3, progress=None)


def test_indices_are_those_of_the_sessions(in_process: StudyResult) -> None:
    v = in_process.values
    names = refine_study.INDEX_NAMES
    assert v.shape == (3, ROBOTS, len(names)) and np.isfinite(v).all()
    col = {n: v[..., k] for k, n in enumerate(names)}
    np.testing.assert_array_equal(col["gain"], col["smodel_rms_cm"] / col["refined_rms_cm"])
    assert np.all(col["refined_max_cm"] >= col["refined_rms_cm"])
    # Common random numbers: one simulate seed per robot, the same at every k.
    assert np.all(col["simulate_seed"] == col["simulate_seed"][0])
    assert len(set(col["simulate_seed"][0])) == ROBOTS
    # The S-Model error grows with the range noise (same deviates, k = 1 -> 10).
    assert np.all(col["smodel_rms_cm"][-1] > 3.0 * col["smodel_rms_cm"][0])
    assert set(np.unique(col["verdict"])) <= {0.0, 1.0, 2.0}
    # The bound at k: k times the bound of the robot's k = 1 session (the documented law).
    k = np.array(in_process.study.values)[:, None]
    np.testing.assert_array_equal(col["crb_cm"], k * col["crb_cm"][0])


def test_same_bits_in_process_in_worker_processes_and_on_dask(in_process: StudyResult) -> None:
    """OpenBLAS's sums depend on its thread count (robot3: other chain bits with 1 and 2
    threads); the study runs each robot with one, wherever it runs."""
    with threadpool_limits(1, user_api="blas"):
        one = run_study(_small(), robots=ROBOTS, seed=3, progress=None)
    np.testing.assert_array_equal(one.values, in_process.values)
    pool = run_study(_small(), robots=ROBOTS, seed=3, workers=2, progress=None)
    np.testing.assert_array_equal(pool.values, in_process.values)
    from pipeline.fleet.engine import dask_client

    with dask_client("local", 2) as client:  # worker processes, as `--scheduler local`
        dask = run_study(_small(), robots=ROBOTS, seed=3, progress=None, client=client)
    np.testing.assert_array_equal(dask.values, in_process.values)


def test_tables_figures_and_report(in_process: StudyResult, tmp_path: Path) -> None:
    d = output.write_study(tmp_path, in_process)
    for f in ("indices.arrow", "summary.arrow", "rms.png", "gain.png", "calibration.png"):
        assert (d / f).is_file(), f
    df = pl.read_ipc(d / "indices.arrow")
    seed = df.filter((pl.col("index") == "simulate_seed") & (pl.col("robot") == 1))
    assert seed["value"].to_list() == [in_process.values[0, 1, -1]] * 3
    assert seed["value_cm"].null_count() == 3  # a seed is not a length
    text = report.write_report(tmp_path).read_text()
    assert "## Refinement against the S-Model" in text and "| refine | 2 | 3 |" in text
    links = re.findall(r"!\[[^\]]*\]\((refine/[^)]+)\)", text)
    assert sorted(links) == ["refine/calibration.png", "refine/gain.png", "refine/rms.png"]
    row = next(ln for ln in text.splitlines() if ln.startswith("| 1 |"))
    gain = np.median(in_process.values[0, :, refine_study.INDEX_NAMES.index("gain")])
    assert f"| {gain:.2f} |" in row


def test_refine_runs_last_in_all() -> None:
    assert LATER[0] == "refine" and STUDY_NAMES[-4:] == ("refine", "compliance", "verdict", "all")


def test_a_failed_session_names_the_simulate_command_that_re_records_it() -> None:
    from pipeline.errors import ArmsigError
    from pipeline.montecarlo.stats import robot_seeds

    seeds = robot_seeds(3, "refine", 0, 1)
    # 2 cycles per position at 10× the noise: the features stage refuses a sweep.
    with pytest.raises(ArmsigError) as err:
        refine_study.refine_all((10.0,), seeds, points=12, repeats=2)
    seed = refine_study.simulate_seed(seeds[0])
    assert f"--seed {seed} --noise-factor 10 --points 12 --repeats 2" in str(err.value)
    assert "\n" not in str(err.value)
