"""Uncertainty propagation (pipeline.refine.uncertainty) against Monte Carlo through the audit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.kinematics.alignment import LEVER_CM, fit_alignment
from pipeline.refine.kinematics import TOOL_POINT, ChainModel
from pipeline.refine.uncertainty import model_error_maps, predict_model, tool_model, tool_poses
from pipeline.rig.audit import _aligned_errors


def _random_chain(seed: int, m: int) -> tuple[ChainModel, np.ndarray]:
    """A 6-joint chain (joint 3 prismatic) of random frames ~40 cm apart, observed at its
    tool point at m random configurations; and its start x."""
    rng = np.random.default_rng(seed)
    n = 6
    F = np.tile(np.eye(4), (n, 1, 1))
    F[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    F[:, :3, 3] = np.cumsum(rng.normal(0, 25, (n, 3)), axis=0)
    pris = np.zeros(n, bool)
    pris[2] = True
    theta = rng.uniform(-1.5, 1.5, (m, n))
    theta[:, 2] = rng.uniform(-10, 10, m)
    base = ChainModel(
        frames0=F, prismatic=pris, link=np.array([n]), theta=np.zeros((1, n)),
        point=np.array([0]), point_names=(TOOL_POINT,),
    )  # fmt: skip
    model = tool_model(base, theta)
    x = np.zeros(model.n_params)
    x[model.point_slice(0)] = F[-1, :3, 3] + rng.normal(0, 15, 3)
    return model, x


def _random_spd(p: int, scale: float, seed: int) -> np.ndarray:
    M = np.random.default_rng(seed).normal(size=(p, p))
    return scale**2 * (M @ M.T / p + 0.05 * np.eye(p))


def test_tool_poses_match_model_positions() -> None:
    model, x = _random_chain(1, 50)
    p, _ = tool_poses(model, x)
    np.testing.assert_allclose(p, model.positions(x), atol=1e-10)


def test_prediction_matches_audit_monte_carlo() -> None:
    """Draw δθ ~ N(0, Σ), perturb the chain, align it to the unperturbed one as the audit
    does (fit_alignment), and compare each draw's mean squared error with the linear
    prediction of the same draw; then the predicted σ with the mean over many draws."""
    model, x = _random_chain(3, 60)
    Sigma = _random_spd(model.n_params, 2e-4, 3)
    A, B = model_error_maps(model, x)
    T0 = _poses(model, x)
    draws = np.random.default_rng(7).multivariate_normal(np.zeros(model.n_params), Sigma, 100)
    for d in draws[:100]:
        T = _poses(model, x + d)
        X, Y = fit_alignment(T0, T)
        TA = X @ T @ Y
        raw = np.mean(np.sum((T[:, :3, 3] - T0[:, :3, 3]) ** 2, axis=1))
        aligned = np.mean(np.sum((TA[:, :3, 3] - T0[:, :3, 3]) ** 2, axis=1))
        rot = _aligned_errors(T0, T).rms_orientation_deg ** 2
        lin_raw = np.mean(np.sum((A[:, :3] @ d) ** 2, axis=1))
        lin_aligned = np.mean(np.sum((B[:, :3] @ d) ** 2, axis=1))
        lin_rot = np.mean(np.sum(np.degrees(B[:, 3:] @ d / (np.sqrt(2) * LEVER_CM)) ** 2, 1))
        # 1 %: the second-order terms of errors of ~1e-3 relative size; a projection that
        # keeps what the alignment absorbs is off by a factor 1.7 here
        assert raw == pytest.approx(lin_raw, rel=0.01)
        assert aligned == pytest.approx(lin_aligned, rel=0.01)
        assert rot == pytest.approx(lin_rot, rel=0.01)
    pred = predict_model(model, x, Sigma)
    many = np.random.default_rng(8).multivariate_normal(np.zeros(model.n_params), Sigma, 40_000)
    for M, sigma in ((A[:, :3], pred.position_cm), (B[:, :3], pred.position_aligned_cm)):
        ms = np.mean(np.sum((M @ many.T) ** 2, axis=1))
        # 2 %: 40,000 draws give the mean square to ~0.5 % (its chi-square spread)
        assert ms == pytest.approx(np.mean(sigma**2), rel=0.02)
    assert np.mean(pred.position_aligned_cm**2) < 0.9 * np.mean(pred.position_cm**2)


def test_alignment_absorbs_a_base_motion() -> None:
    """A parameter error that only moves the whole chain (the base) is fully absorbed."""
    model, x = _random_chain(5, 80)
    J = model.position_jacobian(x)
    # the parameter direction that translates the tool rigidly at every configuration
    shift = np.array([0.3, -0.2, 0.5])
    d = np.linalg.lstsq(J.reshape(-1, model.n_params), np.tile(shift, len(J)), rcond=None)[0]
    resid = J.reshape(-1, model.n_params) @ d - np.tile(shift, len(J))
    assert np.abs(resid).max() < 1e-8  # a pure translation is reachable
    Sigma = np.outer(d, d) * 1e-6
    pred = predict_model(model, x, Sigma)
    assert pred.position_cm.max() > 1e-4
    # 1e-5: the direction is a translation only to the lstsq's ~1e-9 (and it may turn the
    # tool a little, which the alignment weighs too); without the projection the ratio is 1.
    assert pred.position_aligned_cm.max() < 1e-5 * pred.position_cm.max()


def _poses(model: ChainModel, x: np.ndarray) -> np.ndarray:
    p, R = tool_poses(model, x)
    T = np.tile(np.eye(4), (len(p), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = R, p
    return T
