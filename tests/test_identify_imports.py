"""What a cold and a warm `identify` import (issue 18): a cached run needs none of the
heavy libraries, and a run of an unchanged session (its record: pipeline.identify.record)
not even numpy, pyarrow or the runner; a cold one no pyplot, no scipy.stats and no
scipy.optimize. Each run in a fresh interpreter."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from pipeline.features.expected import NOISE_CONFIDENCE, noise_bound

HEAVY = ("scipy.stats", "scipy.optimize", "scipy.spatial", "matplotlib", "pyarrow.compute")
#: armsig's own compute modules: a cached run imports the stage modules (their versions,
#: parameters and inputs), not what their ``compute`` needs (issue 18).
COMPUTE = (
    "pipeline.features.plane",
    "pipeline.features.targets",
    "pipeline.sensor.compensation",
    "pipeline.sensor.geometry",
    "pipeline.kinematics.signature",
    "pipeline.kinematics.true_dh",
    "pipeline.kinematics.alignment",
    "pipeline.kinematics.chain",
    "pipeline.contract.mcap_read",
    "pipeline.stages.recording_points",
)
_PROBE = """
import json, sys
from pipeline.identify import identify
identify(sys.argv[1])
print(json.dumps(sorted(m for m in json.loads(sys.argv[2]) if m in sys.modules)))
"""


def _imported(session: Path, modules: tuple[str, ...] = (*HEAVY, "matplotlib.pyplot")) -> list[str]:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, str(session), json.dumps(modules)],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.splitlines()[-1])  # type: ignore[no-any-return]


@pytest.fixture
def session(identified_session: Path, tmp_path: Path) -> Path:
    d = tmp_path / "s"
    shutil.copytree(identified_session, d)
    return d


def test_cold_run_imports_no_pyplot_no_scipy_stats_no_scipy_optimize(session: Path) -> None:
    shutil.rmtree(session / "stages")
    (session / "signature.json").unlink()
    imported = _imported(session, (*HEAVY, "matplotlib.pyplot", "scipy.interpolate"))
    assert "matplotlib.pyplot" not in imported and "scipy.stats" not in imported
    assert "scipy.interpolate" not in imported  # the speed-of-sound spline: numpy
    assert "scipy.optimize" not in imported  # the design alignment: optim.lm
    assert (session / "report" / "report.md").is_file()


def test_warm_run_imports_none_of_the_heavy_libraries(session: Path) -> None:
    _imported(session)  # writes the report
    assert _imported(session) == []


def test_unchanged_session_imports_no_numpy_no_pyarrow_no_runner(session: Path) -> None:
    _imported(session)  # writes the report and the record
    assert _imported(session, ("numpy", "pyarrow", "pipeline.stages.runner")) == []
    (session / "stages" / ".identified.json").unlink()  # the full check: the runner
    assert _imported(session, ("numpy", "pyarrow", "pipeline.stages.runner")) == [
        "numpy",
        "pipeline.stages.runner",
        "pyarrow",
    ]


def test_warm_run_imports_no_compute_module(session: Path) -> None:
    _imported(session)  # writes the report
    assert _imported(session, COMPUTE) == []


def test_noise_bound_is_the_chi2_quantile_bit_for_bit() -> None:
    # scipy.special.gammaincinv as scipy.stats.chi2.ppf calls it: the same features tables.
    for dof in [*range(1, 200), 997, 5000]:
        q = chi2.ppf((1.0 - NOISE_CONFIDENCE) / 2.0, dof)
        assert noise_bound(dof) == float(np.sqrt(dof / q))
