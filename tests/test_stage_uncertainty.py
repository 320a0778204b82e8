"""Stage ``uncertainty`` on an identified session with a stand-in refine table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from pipeline.errors import StageError
from pipeline.kinematics.chain import forward_kinematics
from pipeline.refine.unmodelled import Unmodelled
from pipeline.schemas import validate_table
from pipeline.stages import uncertainty
from pipeline.stages.frames import chain_from_frames, matrices_from_columns
from pipeline.stages.runner import stage_path
from pipeline.stages.session import session_robot
from pipeline.stages.tables import read_table
from pipeline.units import joints_to_internal


def _refine(frames: pa.Table, n_axis: int, Sigma: np.ndarray, deg: bool) -> pa.Table:
    """Axis rows at δ = 0 and the thesis tool point, with covariance ``Sigma`` (rad, cm)."""
    n = 6
    T = matrices_from_columns(frames)
    tool = (T[n] @ T[n + 1])[:3, 3]
    names = [f"joint{k // 4 + 1}.{'rx ry tx ty'.split()[k % 4]}" for k in range(n_axis)]
    units = [
        "deg" if (k % 4) < 2 and deg else ("rad" if k % 4 < 2 else "cm") for k in range(n_axis)
    ]
    f = np.array([np.degrees(1.0) if u == "deg" else 1.0 for u in units] + [1.0] * 6)
    # a sweep point between the axis rows and the tool: picked by name, not position
    values = np.concatenate([np.zeros(n_axis), [1.0, 2.0, 3.0], tool])
    P = len(values)
    C = np.zeros((P, P))
    keep = np.r_[0:n_axis, n_axis + 3 : P]
    C[np.ix_(keep, keep)] = Sigma
    C = C * np.outer(f, f)
    return pa.table({
        "group": ["axis"] * n_axis + ["point"] * 6,
        "name": names + ["sweep2/sparker.x", "sweep2/sparker.y", "sweep2/sparker.z",
                         "tool.x", "tool.y", "tool.z"],
        "unit": units + ["cm"] * 6,
        "start": values * f, "value": values * f, "sigma": np.sqrt(np.diag(C)),
        "covariance": pa.array(list(C), pa.list_(pa.float64())),
    })  # fmt: skip


def test_uncertainty_stage(identified_session: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    read = lambda name: read_table(stage_path(identified_session, name))  # noqa: E731
    # the stand-in refine table has no fit behind it: its unmodelled error is given
    u = Unmodelled(rms_cm=0.003, residual_rms_cm=0.004, p_value=0.0, points=10)
    monkeypatch.setattr(uncertainty, "_fit_model", lambda inputs: None)
    monkeypatch.setattr(uncertainty, "fit_unmodelled", lambda inputs, fit: u)
    session, frames = read("session"), read("frames")
    n_axis = 24
    rng = np.random.default_rng(0)
    M = rng.normal(size=(n_axis + 3, n_axis + 3))
    Sigma = 1e-8 * (M @ M.T + np.eye(n_axis + 3))
    params = uncertainty.Params(configurations=200, seed=0)
    inputs = {"session": session, "frames": frames}
    t = uncertainty.compute({**inputs, "refine": _refine(frames, n_axis, Sigma, False)}, params)
    validate_table(t, "uncertainty")
    # tool positions: the thesis chain at the audit's configurations (δ = 0)
    robot = session_robot(session)
    lim = robot.limits
    q = np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (200, 6))
    T = forward_kinematics(chain_from_frames(frames, robot.prismatic),
                           joints_to_internal(q, robot.prismatic))  # fmt: skip
    xyz = np.stack([t.column(f"{a}_cm").to_numpy() for a in "xyz"], axis=1)
    np.testing.assert_allclose(xyz, T[:, :3, 3], atol=1e-9)
    # units: the same covariance given in degrees gives the same σ; Σ × 4 doubles σ
    t_deg = uncertainty.compute({**inputs, "refine": _refine(frames, n_axis, Sigma, True)}, params)
    t4 = uncertainty.compute(
        {**inputs, "refine": _refine(frames, n_axis, 4 * Sigma, False)}, params
    )
    s = t.column("sigma_position_aligned_cm").to_numpy()
    np.testing.assert_allclose(t_deg.column("sigma_position_aligned_cm").to_numpy(), s, rtol=1e-9)
    np.testing.assert_allclose(t4.column("sigma_position_aligned_cm").to_numpy(), 2 * s, rtol=1e-9)
    # the total: the parameters' part and the unmodelled part in quadrature (issue 41)
    np.testing.assert_allclose(t.column("sigma_unmodelled_cm").to_numpy(), 0.003)
    total = t.column("sigma_total_cm").to_numpy()
    np.testing.assert_allclose(total, np.sqrt(s**2 + 0.003**2), rtol=1e-12)
    summ = uncertainty.summary(t)
    assert summ is not None
    assert summ["sigma_position_aligned_p95_cm"] <= summ["sigma_position_aligned_max_cm"]
    assert summ["max95_cm"] >= summ["sigma_position_aligned_rms_cm"]
    # disabled refinement: zero rows; a table of another chain: one line
    empty = _refine(frames, n_axis, Sigma, False).slice(0, 0)
    assert uncertainty.compute({**inputs, "refine": empty}, params).num_rows == 0
    assert uncertainty.summary(uncertainty.compute({**inputs, "refine": empty}, params)) is None
    with pytest.raises(StageError, match="does not match the session's chain"):
        uncertainty.compute({**inputs, "refine": _refine(frames, n_axis, Sigma, False).slice(1)},
                            params)  # fmt: skip


def test_the_unmodelled_part_reads_the_fit_residuals(identified_session: Path) -> None:
    """The refined chain's residuals at the fit positions are the refinement's (robot3's
    sonic session: χ²/dof ~1, no unmodelled error, the prediction the parameters' alone)."""
    read = lambda name: read_table(stage_path(identified_session, name))  # noqa: E731
    names = ("session", "refine", "frames", "positions", "joints")
    u = uncertainty.fit_unmodelled({n: read(n) for n in names})
    assert u.rms_cm == 0.0 and u.p_value is None  # a sonic session's is not estimated
    assert 0.01 < u.residual_rms_cm < 0.2  # triangulated noise of 2 cycles a position, 73 points
    t = read("uncertainty")
    np.testing.assert_array_equal(
        t.column("sigma_total_cm").to_numpy(), t.column("sigma_position_aligned_cm").to_numpy()
    )
