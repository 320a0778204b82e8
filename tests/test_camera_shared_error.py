"""The error an image's points share (refine/camera_readings.py, image_pose_variance):
its moment solution is unbiased under its own model, and its test's false alarms are at
the stated level."""

from __future__ import annotations

import numpy as np

from pipeline.refine.camera_readings import SHARED_ALARM, image_pose_variance

M, N, P = 16, 24, 12  # images, points an image, fitted parameters


def _draw(rng: np.random.Generator, w2: float, tau2: float, Q: list, J: np.ndarray) -> tuple:
    """Residuals of a least-squares fit (``J`` whitened at σ = 1 px) to pixels with
    independent errors of variance ``w2`` and a shared ``√n Q_i z_i``, ``z ~ N(0, τ² I₆)``."""
    e = rng.normal(0.0, np.sqrt(w2), 2 * M * N)
    for i, Qi in enumerate(Q):
        e[2 * N * i : 2 * N * (i + 1)] += np.sqrt(N) * Qi @ rng.normal(0.0, np.sqrt(tau2), 6)
    U = np.linalg.qr(J)[0]
    r = e - U @ (U.T @ e)
    return r.reshape(-1, 2)


def _setup(rng: np.random.Generator) -> tuple:
    image = np.repeat(np.arange(M), N)
    Q = [np.linalg.qr(rng.normal(size=(2 * N, 6)))[0] for _ in range(M)]
    # parameters that move whole images (as a hand-eye does) and some that do not
    J = np.concatenate([np.vstack([Qi @ rng.normal(size=(6, 6)) for Qi in Q]),
                        rng.normal(size=(2 * M * N, P - 6))], axis=1)  # fmt: skip
    return image, Q, J


def test_the_moment_solution_is_unbiased_where_the_fit_absorbs_much() -> None:
    """w² 0.15, τ² 0.2 px² (as the real ChArUco set's), 16 images against 12 parameters of
    which 6 move whole images: over 300 draws the estimates' means are within 4 % of the
    truth (the projections without the fit's absorption counted: τ² 10 % low)."""
    rng = np.random.default_rng(4)
    image, Q, J = _setup(rng)
    est = np.array([image_pose_variance(image, _draw(rng, 0.15, 0.2, Q, J), Q, J)
                    for _ in range(300)])  # fmt: skip
    assert np.all(est[:, 1] > 0)  # found every time at this size
    assert abs(est[:, 0].mean() / 0.15 - 1) < 0.04
    assert abs(est[:, 1].mean() / 0.2 - 1) < 0.04


def test_without_a_shared_error_it_is_found_at_the_false_alarm_level() -> None:
    rng = np.random.default_rng(5)
    image, Q, J = _setup(rng)
    found = [image_pose_variance(image, _draw(rng, 0.04, 0.0, Q, J), Q, J)[1] > 0
             for _ in range(400)]  # fmt: skip
    assert np.mean(found) < 3 * SHARED_ALARM  # 400 draws: 1 % expected


def test_known_shares_are_taken_off_and_noiseless_gives_nothing() -> None:
    rng = np.random.default_rng(6)
    image, Q, J = _setup(rng)
    r = _draw(rng, 0.15, 0.2, Q, J)
    w2, tau2 = image_pose_variance(image, r, Q, J)
    w2k, tau2k = image_pose_variance(image, r, Q, J, np.full(M, 6.0 * N * 0.05))
    assert w2k > 0 and tau2k < tau2  # a share already counted lowers the estimate
    assert image_pose_variance(image, np.zeros_like(r), Q, J) == (0.0, 0.0)
