import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


def random_rigid(rng: np.random.Generator, n: int, scale: float = 50.0) -> np.ndarray:
    """n random rigid transforms: uniform rotations, Gaussian translations (cm)."""
    Q, R = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    Q = Q * np.sign(np.diagonal(R, axis1=-2, axis2=-1))[:, None, :]
    Q[np.linalg.det(Q) < 0, :, 0] *= -1
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Q
    T[:, :3, 3] = rng.normal(scale=scale, size=(n, 3))
    return T


@pytest.fixture(scope="session")
def identified_session(tmp_path_factory: pytest.TempPathFactory):
    """A small simulated session, identified without a report. Tests that change files
    work on a copy: ``shutil.copytree(identified_session, tmp_path / "s")``."""
    from pipeline.identify import identify
    from pipeline.rig.simulate import SimulationOptions, simulate_session

    d = tmp_path_factory.mktemp("identified") / "s"
    simulate_session(d, SimulationOptions(seed=2, points=12, repeats=2))
    identify(d, report=False)
    return d


@pytest.fixture(scope="session")
def robot3_identified(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The committed robot3 recording (recording.mcap alone), identified without a report:
    once per test process. Read it, or work on a copy: ``shutil.copytree`` to a folder
    of your own (tests/test_control.py, test_export.py, test_identify.py)."""
    from pipeline.identify import identify

    d = tmp_path_factory.mktemp("robot3-identified") / "robot3"
    d.mkdir()
    shutil.copy(ROOT / "sessions" / "robot3" / "recording.mcap", d)
    identify(d, report=False)
    return d


@pytest.fixture
def read_only_dir(tmp_path: Path) -> Iterator[Path]:
    """An empty folder nobody may write in (skipped as root, who writes anyway)."""
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    yield ro
    ro.chmod(0o755)
