"""Uncertainty propagation (pipeline.refine.uncertainty) against Monte Carlo through the audit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.audit import _aligned_errors
from pipeline.kinematics.alignment import fit_alignment
from pipeline.refine.kinematics import TOOL_POINT, ChainModel
from pipeline.refine.uncertainty import predict_model, tool_model, tool_poses


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


@pytest.mark.parametrize("seed", [3, 4])
def test_prediction_matches_audit_monte_carlo(seed: int) -> None:
    """Draw δθ ~ N(0, Σ), perturb the chain, align it to the unperturbed one as the audit
    does, and compare the mean squared errors with the predicted ones."""
    model, x = _random_chain(seed, 150)
    Sigma = _random_spd(model.n_params, 2e-4, seed)
    pred = predict_model(model, x, Sigma)
    T0 = _poses(model, x)
    rng = np.random.default_rng(seed + 100)
    draws = rng.multivariate_normal(np.zeros(model.n_params), Sigma, 300)
    raw, aligned, rot = [], [], []
    for d in draws:
        T = _poses(model, x + d)
        raw.append(np.mean(np.sum((T[:, :3, 3] - T0[:, :3, 3]) ** 2, axis=1)))
        X, Y = fit_alignment(T0, T)
        TA = X @ T @ Y
        aligned.append(np.mean(np.sum((TA[:, :3, 3] - T0[:, :3, 3]) ** 2, axis=1)))
        rot.append(_aligned_errors(T0, T).rms_orientation_deg ** 2)
    for mc, predicted in (
        (raw, pred.position_cm),
        (aligned, pred.position_aligned_cm),
        (rot, pred.orientation_aligned_deg),
    ):
        mc_ms, pred_ms = np.mean(mc), np.mean(predicted**2)
        sem = np.std(mc) / np.sqrt(len(mc))
        # MC standard error ~2 % here; a wrong projection (e.g. no alignment, or the
        # rotation weight off by √2) changes the aligned mean square by far more.
        assert abs(mc_ms / pred_ms - 1) < max(3 * sem / pred_ms, 0.03), (mc_ms, pred_ms, sem)
    assert pred.position_aligned_cm.mean() < 0.9 * pred.position_cm.mean()


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
