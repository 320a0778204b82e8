"""Is the camera's per-seed audited/predicted spread genuine or a bias? (issue 39)

For each noisy session the audited tool error ``e`` (the stacked 3-D errors at the
audit's 1,000 configurations, against ``rig-truth.json``) is split along the principal
directions of its prediction: with ``A`` the tool points' Jacobian at those
configurations and ``Σ`` the fit's covariance of the chain, ``A Σ Aᵀ = Σ λ_i u_i u_iᵀ``
and ``z_i = u_iᵀ e / √λ_i``. A right covariance gives ``z_i ~ N(0, 1)``, independent:

- ``k_eff = (Σ λ)² / Σ λ²``, the error's effective dimension: the per-seed ratio
  audited/predicted is ``sqrt(Σ λ_i z_i² / Σ λ_i)``, a χ² of about ``k_eff`` degrees of
  freedom over ``k_eff``, so its spread is genuine when ``k_eff`` is small;
- ``mean z²`` over the directions that hold 99 % of the trace: ≈ 1 without bias (its
  standard error over ``K`` directions is ``√(2 / K)`` per session), > 1 when the fit
  predicts its error low.

Noise models on the same poses separate the causes: ``pixels`` (a noiseless session,
Gaussian pixel noise added to its detections: the fit's own noise model exactly),
``pixels, linear loss`` (the same without the robust loss, ``BENCH_CAMERA_LINEAR=1``),
and the simulator's default (0.2 px and its servo and encoder rounding) with the fit's
covariance of the pixels alone or with the readings' rounding
(:mod:`pipeline.refine.camera_readings`). ``python -m bench.camera_spread``;
``BENCH_CAMERA_SEEDS`` seeds (default 5).
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa

from bench.camera import ROBOTS, get_desc, tables
from pipeline.kinematics.chain import link_frames
from pipeline.refine.camera_fit import fit_camera, observing
from pipeline.rig.audit import true_chain
from pipeline.rig.camera_audit import true_hand_eye
from pipeline.rig.simulate import SimulationOptions, simulate_session
from pipeline.stages import camera_fit

SEEDS = int(os.environ.get("BENCH_CAMERA_SEEDS", "5"))
#: ``BENCH_CAMERA_LINEAR=1``: the pixel-noise sessions also without the robust loss.
LINEAR = os.environ.get("BENCH_CAMERA_LINEAR", "") == "1"
NOISES = ("pixels", *(("pixels, linear loss",) if LINEAR else ()), "default, pixels weighed",
          "default, readings weighed")  # fmt: skip
PIXEL_NOISE = 0.2
#: Directions holding this share of the predicted error's trace are scored.
TRACE_SHARE = 0.99


def with_pixel_noise(t: dict, seed: int) -> dict:
    """The tables with Gaussian noise of :data:`PIXEL_NOISE` px added to the detections."""
    det = t["detections"]
    rng = np.random.default_rng(1000 + seed)
    out = dict(t)
    for c in ("u_px", "v_px"):
        v = det.column(c).to_numpy() + rng.normal(0.0, PIXEL_NOISE, det.num_rows)
        det = det.set_column(det.schema.get_field_index(c), c, pa.array(v))
    sigma = np.full(det.num_rows, PIXEL_NOISE)
    out["detections"] = det.set_column(det.schema.get_field_index("sigma_px"), "sigma_px",
                                       pa.array(sigma))  # fmt: skip
    return out


def scores(d: Path, t: dict, loss: str, readings: bool) -> dict:
    """k_eff, the audited/predicted ratio and the mean z² of one fit (module docstring);
    ``readings``: the fit's covariance with the joint readings' rounding."""
    det, design, lens, setup = camera_fit.detections_for_fit(t)
    sigma_q = camera_fit.reading_sigma(t["session"]) if readings else None
    fit = fit_camera(det, design, lens, setup, loss=loss, reading_sigma=sigma_q)
    truth = json.loads((d / "rig-truth.json").read_text())
    desc = get_desc(t)
    q = desc.random_configurations(1000, 0)  # the audit's configurations
    _, on_flange = true_hand_eye(truth)
    p_true = (link_frames(true_chain(truth), q)[:, desc.n_joints] @ on_flange)[:, :3, 3]
    e = (p_true - fit.tool_poses(q, det.q_signature)[:, :3, 3]).reshape(-1)
    n = fit.model.n_params
    A = observing(fit.model, q, det.q_signature).position_jacobian(fit.solution.x[:n])
    w, V = np.linalg.eigh(fit.solution.covariance[:n, :n])
    M = A.reshape(-1, n) @ (V * np.sqrt(np.clip(w, 0.0, None)))
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    lam = s**2
    k = int(np.searchsorted(np.cumsum(lam) / lam.sum(), TRACE_SHARE)) + 1
    z = (U[:, :k].T @ e) / s[:k]
    return {
        "k_eff": float(lam.sum() ** 2 / np.sum(lam**2)),
        "ratio": float(np.sqrt(np.sum(e**2) / lam.sum())),
        "z2": float(np.mean(z**2)),
        "k": k,
        "noise_scale": fit.solution.noise_scale,
    }


def expected_ratios(lam_share: np.ndarray, draws: int = 20000) -> np.ndarray:
    """Draws of audited/predicted for an error of eigenvalue shares ``lam_share``."""
    z = np.random.default_rng(0).standard_normal((draws, len(lam_share)))
    return np.asarray(np.sqrt((z**2) @ lam_share))


def main() -> None:
    print(f"camera per-seed spread (issue 39): {SEEDS} seeds, 0.2 px; per row the median over "
          "the seeds of k_eff and of the ratio, the ratios' min-max, the mean z² over every "
          "scored direction of every seed (1: no bias), the fitted noise scale")  # fmt: skip
    print(
        "robot | setup | images | noise | k_eff | aud/pred median (min-max) | RMS | "
        "mean z² (dirs) | s"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for name, robot in ROBOTS:
            for setup in ("eye-to-hand", "eye-in-hand"):
                for images in (40, 150):
                    _rows(Path(tmp), name, robot, setup, images)


def _rows(tmp: Path, name: str, robot: str, setup: str, images: int) -> None:
    runs: dict[str, list[dict]] = {k: [] for k in NOISES}
    for seed in range(1, SEEDS + 1):
        d = tmp / f"n{seed}"
        simulate_session(d, SimulationOptions(robot=robot, sensor="camera", setup=setup,
                         poses=images, seed=seed, noiseless=True), force=True)  # fmt: skip
        t = with_pixel_noise(tables(d), seed)
        runs["pixels"].append(scores(d, t, "soft_l1", False))
        if LINEAR:
            runs["pixels, linear loss"].append(scores(d, t, "linear", False))
        d = tmp / f"s{seed}"
        simulate_session(d, SimulationOptions(robot=robot, sensor="camera", setup=setup,
                         poses=images, seed=seed), force=True)  # fmt: skip
        t = tables(d)
        runs["default, pixels weighed"].append(scores(d, t, "soft_l1", False))
        runs["default, readings weighed"].append(scores(d, t, "soft_l1", True))
    for noise, rows in runs.items():
        r = [x["ratio"] for x in rows]
        z2 = sum(x["z2"] * x["k"] for x in rows) / sum(x["k"] for x in rows)
        cells = (
            name, setup, images, noise, f"{statistics.median(x['k_eff'] for x in rows):.1f}",
            f"{statistics.median(r):.2f} ({min(r):.2f}-{max(r):.2f})",
            f"{np.sqrt(np.mean(np.square(r))):.2f}",
            f"{z2:.2f} ({sum(x['k'] for x in rows)})",
            f"{statistics.median(x['noise_scale'] for x in rows):.3f}",
        )  # fmt: skip
        print(" | ".join(map(str, cells)), flush=True)


if __name__ == "__main__":
    main()
