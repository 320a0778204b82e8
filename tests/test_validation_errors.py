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
