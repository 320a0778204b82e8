"""Model position errors on validation points: as is and after registering the base."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.evaluation.validation import error_distances, position_errors, register_rigid


def test_registration_removes_a_rigid_motion_only() -> None:
    rng = np.random.default_rng(4)
    model = rng.normal(0, 30, (20, 3))
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    measured = model @ R.T + [5.0, -2.0, 1.0]
    T = register_rigid(model, measured)
    assert T is not None
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-12)
    raw, reg = error_distances(model, measured)
    assert raw.max() > 1.0 and reg is not None and reg.max() < 1e-9
    # a non-rigid error stays after the registration
    bent = measured.copy()
    bent[0] += [0.5, 0.0, 0.0]
    _, reg = error_distances(model, bent)
    assert reg is not None and reg.max() > 0.3


def test_collinear_points_are_not_registered() -> None:
    line = np.outer(np.arange(5.0), [1.0, 2.0, 3.0])
    assert register_rigid(line, line + 1.0) is None
    e = position_errors(*error_distances(line, line + [0.0, 0.0, 1.0]))
    assert e.n == 5 and e.mean_cm == pytest.approx(1.0) and e.registered_rms_cm is None


def test_tracker_check_configurations_are_validated(tmp_path_factory) -> None:
    """A simulated tracker session with validation configurations: the stage compares them
    (exact when noiseless) and, its sweep targets sitting on the links, only the tool
    measurement as fit data."""
    from recording_data import small_session

    from pipeline.identify import identify
    from pipeline.stages.tables import read_table

    d = small_session(tmp_path_factory, sensor="tracker", seed=3, noiseless=True, points=5,
                      check=7)  # fmt: skip
    identify(d, report=True)
    rows = read_table(d / "stages" / "validation.arrow").to_pylist()
    check = [r for r in rows if r["role"] == "check"]
    fit = [r for r in rows if r["role"] == "fit"]
    assert len(check) == 7 and {r["sweep"] for r in fit} == {0}
    assert max(r["error_cm"] for r in check) <= 1e-6
    assert max(r["registered_error_cm"] for r in check) <= 1e-6
    assert (
        "validation configurations (not used by the fit) | 7 |"
        in (d / "report" / "report.md").read_text()
    )
